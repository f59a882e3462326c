"""The verdict of one closed-loop run, pure: from the run's timeline to "collision avoided
or impact speed", when and at what TTC the first BRAKE came, the stopping distance, and
false activations in no-threat scenarios.
"""

from dataclasses import dataclass

from aeb_radar_camera.tools.sim.scenario import ScenarioKind
from aeb_radar_camera.tools.sim.world import Collision

# The actuator counts as braking above this position (a released actuator may read a
# percent or two).
BRAKING_POSITION_PCT = 5.0
STOPPED_MPS = 0.05


@dataclass(frozen=True)
class Sample:
    """The closed loop at one tick of the simulator."""

    t_s: float
    ego_x_m: float
    ego_speed_mps: float
    gap_m: float | None          # ground truth: nearest object in the ego's path (or the
                                 # one it would hit), None when none
    ttc_s: float | None          # ground truth: time until it would hit something at
                                 # current velocities, None when nothing would be hit
    decision: str                # the followed fusion instance's latest decision ("" before any)
    brake_state: str             # the brake service's latest state ("" before any)
    commanded_pct: float         # level in the last command the actuator received
    position_pct: float          # actuator position
    false_target_gap_m: float | None = None   # nearest false target in the ego's width


@dataclass(frozen=True)
class Verdict:
    scenario: str
    kind: ScenarioKind
    passed: bool
    outcome: str
    collision: bool
    impact_speed_kph: float | None
    first_brake_t_s: float | None      # first BRAKE decision
    first_brake_ttc_s: float | None    # ground-truth TTC at that moment
    first_brake_gap_m: float | None
    actuation_t_s: float | None        # actuator position first above BRAKING_POSITION_PCT
    stopping_distance_m: float | None  # first BRAKE to standstill
    min_gap_m: float | None            # closest gap to an object in (or entering) the path
    brake_activations: int             # episodes of the actuator being commanded to brake
    false_activations: int             # activations in a no-threat scenario
    warnings: int                      # WARNING episodes
    duration_s: float


def _episodes(flags: list[bool]) -> int:
    count, prev = 0, False
    for f in flags:
        if f and not prev:
            count += 1
        prev = f
    return count


def judge(name: str, kind: ScenarioKind, samples: list[Sample],
          collision: Collision | None) -> Verdict:
    """The verdict of a run. Raises ValueError for an empty timeline."""
    if not samples:
        raise ValueError(f"{name}: no samples to judge")
    first_brake = next((s for s in samples if s.decision == "BRAKE"), None)
    actuated = next((s for s in samples if s.position_pct > BRAKING_POSITION_PCT), None)
    activations = _episodes([s.commanded_pct > 0 for s in samples])
    warnings = _episodes([s.decision == "WARNING" for s in samples])
    stopping = None
    if first_brake is not None and collision is None:
        stop = next((s for s in samples if s.t_s >= first_brake.t_s
                     and s.ego_speed_mps <= STOPPED_MPS), None)
        if stop is not None:
            stopping = stop.ego_x_m - first_brake.ego_x_m
    last = samples[-1]
    if kind is ScenarioKind.THREAT:
        false_activations = 0
        passed = collision is None
        if collision is not None:
            outcome = f"collision at {collision.ego_speed_mps * 3.6:.1f} km/h"
        elif last.ego_speed_mps <= STOPPED_MPS:
            outcome = "avoided (stopped)"
        else:
            outcome = "avoided"
    else:
        false_activations = activations
        passed = activations == 0 and collision is None
        if collision is not None:
            outcome = f"collision at {collision.ego_speed_mps * 3.6:.1f} km/h"
        elif activations:
            outcome = f"{activations} false activation{'s' if activations > 1 else ''}"
        else:
            outcome = "no activation"
    return Verdict(
        scenario=name, kind=kind, passed=passed, outcome=outcome,
        collision=collision is not None,
        impact_speed_kph=collision.ego_speed_mps * 3.6 if collision else None,
        first_brake_t_s=first_brake.t_s if first_brake else None,
        first_brake_ttc_s=first_brake.ttc_s if first_brake else None,
        first_brake_gap_m=first_brake.gap_m if first_brake else None,
        actuation_t_s=actuated.t_s if actuated else None,
        stopping_distance_m=stopping,
        min_gap_m=min((x.gap_m for x in samples if x.gap_m is not None), default=None),
        brake_activations=activations,
        false_activations=false_activations,
        warnings=warnings,
        duration_s=last.t_s,
    )


def _fmt(value: float | None, unit: str, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}{unit}"


SUMMARY_HEADER = (f"{'scenario':<42} {'kind':<9} {'result':<6} {'outcome':<22} "
                  f"{'1st BRAKE':>9} {'TTC':>6} {'min gap':>7} {'stop dist':>9} {'false':>5}")


def summary_line(v: Verdict) -> str:
    return (f"{v.scenario:<42} {v.kind.value:<9} {'PASS' if v.passed else 'FAIL':<6} "
            f"{v.outcome:<22} {_fmt(v.first_brake_t_s, 's'):>9} "
            f"{_fmt(v.first_brake_ttc_s, 's'):>6} {_fmt(v.min_gap_m, 'm'):>7} "
            f"{_fmt(v.stopping_distance_m, 'm'):>9} {v.false_activations:>5}")
