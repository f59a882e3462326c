"""The test grid's scoring, pure: each case's timeline (tools/sim/verdict.Sample) to what
Euro NCAP-style testing reads from it, and the cases of a family to its points.

Per case: avoided or the impact speed; time and ground-truth TTC of the first WARNING
and the first BRAKE; the reaction time from the first moment an object is in the ego's
path (or on a collision course with it: the timeline's `gap_m`) within the radar's reach
(the paper's rule: the radar service's prefilter range; the kinematic rule: its range
gate at the ego's speed) to the first BRAKE command and to the actuator at 50 %; the lag
from the moment a brake was due (in reach and, on the ground truth, the paper's TTC bound
(TTC_eff + offset) or the kinematic rule's first braking stage: `Reach`) to the first
BRAKE. Both are set
beside the floor the sensors set (`SensorFloor`): the radar's confirmation cycles, a
camera frame period and the loop's modelled delays - no system built of these sensors
brakes sooner after a threat appears.

Points (Euro NCAP-style, not Euro NCAP's own weights): a threat case is worth 1 point,
all of it when the collision was avoided, else the share of the ego's speed taken off
before the impact, (v - v_impact) / v; a no-threat case is worth 1 point when the brake
was never commanded (and nothing was hit), else 0. A family's score is its points over
its cases, in percent.
"""

import math
import statistics
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from aeb_radar_camera.common.config.fusion import RuleName
from aeb_radar_camera.tools.sim.scenario import ScenarioKind
from aeb_radar_camera.tools.sim.verdict import Sample, Verdict

if TYPE_CHECKING:
    from aeb_radar_camera.tools.grid.lockstep import FusionCycle, LoopConfig

HALF_POSITION_PCT = 50.0
# The simulated actuator's first-order time constant (tools/sim/actuator.py's default,
# which the lockstep brake runs with).
ACTUATOR_TAU_S = 0.15


@dataclass(frozen=True)
class SensorFloor:
    """The shortest reaction the sensors allow: `confirm_cycles` radar cycles of
    `radar_cycle_s` (the tracker confirms a track on its Nth consecutive detection; the
    first comes up to a cycle after the object appears), a camera frame period (the
    frame that shows it), the modelled delays (CAN link, radar processing, the Zenoh
    hops, fusion, brake, serial, the camera frame's way to fusion), and to 50 % the
    actuator's rise to half position at the commanded level."""

    confirm_cycles: int
    radar_cycle_s: float
    frame_period_s: float
    delays_s: float
    actuator_half_s: float

    @property
    def brake_s(self) -> float:
        """In reach -> the first BRAKE command on the actuator's line."""
        return (self.confirm_cycles * self.radar_cycle_s + self.frame_period_s
                + self.delays_s)

    @property
    def half_s(self) -> float:
        """In reach -> the actuator at 50 %."""
        return self.brake_s + self.actuator_half_s

    def describe(self) -> str:
        return (f"{self.confirm_cycles} x {self.radar_cycle_s * 1000:.0f} ms radar cycles + "
                f"{self.frame_period_s * 1000:.0f} ms frame + {self.delays_s * 1000:.1f} ms "
                f"delays = {self.brake_s * 1000:.0f} ms to BRAKE; + "
                f"{self.actuator_half_s * 1000:.0f} ms actuator = {self.half_s * 1000:.0f} ms "
                f"to 50 %")


def actuator_half_s(level_pct: float, tau_s: float = ACTUATOR_TAU_S) -> float:
    """A first-order actuator from rest to 50 % when commanded to `level_pct`; inf when the
    level never gets there. Raises ValueError for a non-positive tau."""
    if tau_s <= 0:
        raise ValueError("tau_s must be positive")
    if level_pct <= HALF_POSITION_PCT:
        return math.inf
    return tau_s * math.log(level_pct / (level_pct - HALF_POSITION_PCT))


def sensor_floor(config: "LoopConfig", tau_s: float = ACTUATOR_TAU_S) -> SensorFloor:
    """The floor of a loop configuration: its radar tracker's confirmation, the loop's
    mean radar cycle, its camera's frame period, its modelled delays, its fusion's
    brake level."""
    lo, hi = config.loop.radar_period_s
    d = config.delays
    delays_ns = d.radar_to_brake_ns + d.camera_frame_ns
    return SensorFloor(
        confirm_cycles=config.radar.tracker.confirm_hits,
        radar_cycle_s=(lo + hi) / 2,
        frame_period_s=1.0 / config.camera.fps,
        delays_s=delays_ns / 1e9,
        actuator_half_s=actuator_half_s(config.fusion.fusion.decision.brake_level_pct, tau_s))


@dataclass(frozen=True)
class Reach:
    """What the scoring needs of a configuration: the decision's reach (m) and when a
    BRAKE is due on the ground truth. The paper's rule: the radar's prefilter range and
    its TTC bound (TTC_eff + offset). The kinematic rule: its range gate, which follows
    the ego's speed (`range_base_m` + `range_time_s` x v, at most `range_m`), and its
    first braking stage - the ground-truth TTC under `brake_ttc_s`, or a stop short of
    the object needing `brake_decel_mps2` after `latency_s` and `stop_margin_m`."""

    range_m: float
    brake_ttc_s: float
    range_base_m: float | None = None
    range_time_s: float = 0.0
    brake_decel_mps2: float | None = None
    stop_margin_m: float = 0.0
    latency_s: float = 0.0

    @classmethod
    def of(cls, config: "LoopConfig") -> "Reach":
        d = config.fusion.fusion.decision
        if d.rule is not RuleName.KINEMATIC:
            return cls(config.radar.prefilter.max_range_m,
                       d.ttc_offset_s + d.brake_ttc_eff_s)
        k = d.kinematic
        reach = min(k.range_max_m, d.path.length_m, config.radar.prefilter.max_range_m)
        return cls(reach, k.partial_ttc_s,
                   range_base_m=k.range_base_m, range_time_s=k.range_time_s,
                   brake_decel_mps2=k.partial_decel_mps2, stop_margin_m=k.stop_margin_m,
                   latency_s=k.latency_s)

    def reach_m(self, ego_mps: float) -> float:
        if self.range_base_m is None:
            return self.range_m
        return min(self.range_m, self.range_base_m + self.range_time_s * max(ego_mps, 0.0))

    def in_reach(self, s: Sample) -> bool:
        return s.gap_m is not None and s.gap_m <= self.reach_m(s.ego_speed_mps)

    def due(self, s: Sample) -> bool:
        if not self.in_reach(s) or s.ttc_s is None or s.gap_m is None:
            return False
        if s.ttc_s <= self.brake_ttc_s:
            return True
        if self.brake_decel_mps2 is None or s.ttc_s <= 0.0:
            return False
        closing = s.gap_m / s.ttc_s
        room = s.gap_m - self.stop_margin_m - s.ego_speed_mps * self.latency_s
        return room <= 0.0 or closing * closing / (2.0 * room) >= self.brake_decel_mps2


@dataclass(frozen=True)
class Shadow:
    """Where a candidate in shadow mode decided differently from the followed instance:
    the cycles that differ, the first of them (run time, followed -> candidate), and each
    one's first BRAKE."""

    cycles: int
    differing: int
    first_t_s: float | None = None
    first: str = ""
    primary_brake_t_s: float | None = None
    candidate_brake_t_s: float | None = None


@dataclass(frozen=True)
class CaseScore:
    """One case scored. Times are run times (s from the scenario's start); None: never
    happened (or, for the reaction times, no object came in reach, or no brake)."""

    name: str
    family: str
    group: str
    kind: str
    config: str
    speed_kph: float
    params: dict[str, Any]
    seed: int
    passed: bool
    outcome: str
    collision: bool
    impact_speed_kph: float | None
    points: float
    false_activations: int
    first_warning_t_s: float | None
    first_warning_ttc_s: float | None
    first_brake_t_s: float | None
    first_brake_ttc_s: float | None
    half_t_s: float | None               # actuator first at 50 %
    in_reach_t_s: float | None           # an object in the path within the radar's reach
    due_t_s: float | None                # ... and its TTC under the BRAKE bound
    reaction_brake_s: float | None       # in reach -> first BRAKE (negative: before)
    reaction_half_s: float | None        # in reach -> actuator at 50 %
    lag_brake_s: float | None            # due -> first BRAKE
    why: str = ""                        # a collision: why it was not avoided (miss_reason)
    shadow: Shadow | None = None
    error: str = ""

    @property
    def avoided(self) -> bool:
        return self.kind == ScenarioKind.THREAT.value and not self.collision and not self.error


def _first(samples: Iterable[Sample], test: Any) -> Sample | None:
    return next((s for s in samples if test(s)), None)


def case_points(kind: ScenarioKind, speed_kph: float, verdict: Verdict) -> float:
    """The case's points (module docstring)."""
    if kind is ScenarioKind.THREAT:
        if not verdict.collision:
            return 1.0
        impact = verdict.impact_speed_kph or 0.0
        return max(0.0, (speed_kph - impact) / speed_kph) if speed_kph > 0 else 0.0
    return 1.0 if verdict.brake_activations == 0 and not verdict.collision else 0.0


def score_case(samples: Sequence[Sample], verdict: Verdict, reach: Reach, *, name: str,
               family: str, group: str, config: str, speed_kph: float,
               params: dict[str, Any], seed: int, shadow: Shadow | None = None,
               reasons: Sequence[tuple[float, Sequence[str]]] = ()) -> CaseScore:
    """One case's score from its timeline and verdict (`reasons`: fusion's per cycle, for
    why a collision was not avoided). Raises ValueError for an empty timeline."""
    if not samples:
        raise ValueError(f"{name}: no samples to score")
    warning = _first(samples, lambda s: s.decision == "WARNING")
    brake = _first(samples, lambda s: s.decision == "BRAKE")
    half = _first(samples, lambda s: s.position_pct >= HALF_POSITION_PCT)
    in_reach = _first(samples, reach.in_reach)
    due = _first(samples, reach.due)
    threat = verdict.kind is ScenarioKind.THREAT

    def since(a: Sample | None, b: Sample | None) -> float | None:
        return b.t_s - a.t_s if a is not None and b is not None and threat else None

    return CaseScore(
        name=name, family=family, group=group, kind=verdict.kind.value, config=config,
        speed_kph=speed_kph, params=params, seed=seed, passed=verdict.passed,
        outcome=verdict.outcome, collision=verdict.collision,
        impact_speed_kph=verdict.impact_speed_kph,
        points=case_points(verdict.kind, speed_kph, verdict),
        false_activations=verdict.false_activations,
        first_warning_t_s=warning.t_s if warning else None,
        first_warning_ttc_s=warning.ttc_s if warning else None,
        first_brake_t_s=brake.t_s if brake else None,
        first_brake_ttc_s=brake.ttc_s if brake else None,
        half_t_s=half.t_s if half else None,
        in_reach_t_s=in_reach.t_s if in_reach else None,
        due_t_s=due.t_s if due else None,
        reaction_brake_s=since(in_reach, brake), reaction_half_s=since(in_reach, half),
        lag_brake_s=since(due, brake),
        why=(miss_reason(reasons, samples[-1].t_s, brake.ttc_s if brake else None,
                         brake is not None) if verdict.collision else ""),
        shadow=shadow)


MISS_WINDOW_S = 2.0
# What fusion said of its targets, most telling first (services/fusion/decision.py's words)
_MISS_CATEGORIES = (
    ("camera rejected", "the camera check rejected it"),
    ("camera not visible", "not visible to the camera"),
    ("camera unavailable", "camera check unavailable"),
    ("out of corridor", "outside the corridor"),
    ("out of path", "outside the predicted path"),
    ("no stage reached", "verified, no braking stage reached"),
    ("verified, ", "verified, TTC not under the BRAKE bound"),
    ("TTC_eff", "TTC above the bounds"),
    ("not closing", "not closing"),
    ("range", "outside the decision's range"),
)


def miss_reason(reasons: Sequence[tuple[float, Sequence[str]]], impact_t_s: float,
                brake_ttc_s: float | None, braked: bool, window_s: float = MISS_WINDOW_S
                ) -> str:
    """Why a collision was not avoided: braked too late (the TTC at the first BRAKE), or
    what fusion said of its targets in most of the cycles of the last `window_s` before
    the impact (each cycle by its most telling reason), or no track at all."""
    if braked:
        return ("braked late" if brake_ttc_s is None
                else f"braked late (TTC {brake_ttc_s:.2f} s at the first BRAKE)")
    window = [texts for t, texts in reasons if impact_t_s - window_s <= t <= impact_t_s]
    if not window:
        return "no radar cycle before the impact"
    counts: dict[str, int] = {}
    for texts in window:
        label = "no confirmed track"
        for key, what in _MISS_CATEGORIES:
            if any(key in text for text in texts):
                label = what
                break
        else:
            if texts:
                label = "other: " + texts[0][:40]
        counts[label] = counts.get(label, 0) + 1
    label, n = max(counts.items(), key=lambda kv: kv[1])
    return f"{label} ({n} of {len(window)} cycles in the last {window_s:g} s)"


def failed_case(*, name: str, family: str, group: str, kind: ScenarioKind, config: str,
                speed_kph: float, params: dict[str, Any], seed: int, error: str) -> CaseScore:
    """A case that could not run: no points, its error."""
    return CaseScore(name=name, family=family, group=group, kind=kind.value, config=config,
                     speed_kph=speed_kph, params=params, seed=seed, passed=False,
                     outcome="error", collision=False, impact_speed_kph=None, points=0.0,
                     false_activations=0, first_warning_t_s=None, first_warning_ttc_s=None,
                     first_brake_t_s=None, first_brake_ttc_s=None, half_t_s=None,
                     in_reach_t_s=None, due_t_s=None, reaction_brake_s=None,
                     reaction_half_s=None, lag_brake_s=None, error=error)


def reasons_of(cycles: Sequence["FusionCycle"]) -> list[tuple[float, list[str]]]:
    """Each cycle's run time and its targets' decision reasons."""
    return [(c.t_s, [t.reason for t in c.targets.targets]) for c in cycles]


def shadow_of(cycles: Sequence["FusionCycle"]) -> Shadow | None:
    """The candidate's differences over a run's cycles; None without a candidate."""
    pairs = [(c.t_s, c.command.decision.value, c.candidate.command.decision.value)
             for c in cycles if c.candidate is not None]
    if not pairs:
        return None
    return shadow_diff(pairs)


def shadow_diff(pairs: Sequence[tuple[float, str, str]]) -> Shadow:
    """(run time, followed decision, candidate decision) per cycle -> Shadow."""
    differ = [(t, a, b) for t, a, b in pairs if a != b]
    first = differ[0] if differ else None
    return Shadow(
        cycles=len(pairs), differing=len(differ),
        first_t_s=first[0] if first else None,
        first=f"{first[1]} -> {first[2]}" if first else "",
        primary_brake_t_s=next((t for t, a, _ in pairs if a == "BRAKE"), None),
        candidate_brake_t_s=next((t for t, _, b in pairs if b == "BRAKE"), None))


@dataclass
class FamilyScore:
    """A family's cases under one configuration, summed up."""

    family: str
    group: str
    kind: str
    config: str
    cases: int = 0
    errors: int = 0
    passed: int = 0
    avoided: int = 0
    collisions: int = 0
    points: float = 0.0
    impact_speeds_kph: list[float] = field(default_factory=list)
    false_activation_cases: int = 0
    false_activations: int = 0
    reaction_brake_s: list[float] = field(default_factory=list)
    reaction_half_s: list[float] = field(default_factory=list)
    lag_brake_s: list[float] = field(default_factory=list)
    shadow_cases: int = 0            # cases where a candidate decided differently

    @property
    def score_pct(self) -> float:
        return 100.0 * self.points / self.cases if self.cases else 0.0

    @property
    def mean_impact_kph(self) -> float | None:
        return statistics.fmean(self.impact_speeds_kph) if self.impact_speeds_kph else None

    @property
    def max_impact_kph(self) -> float | None:
        return max(self.impact_speeds_kph) if self.impact_speeds_kph else None

    def as_dict(self) -> dict[str, Any]:
        return {"family": self.family, "group": self.group, "kind": self.kind,
                "config": self.config, "cases": self.cases, "errors": self.errors,
                "passed": self.passed, "avoided": self.avoided,
                "collisions": self.collisions, "points": round(self.points, 3),
                "score_pct": round(self.score_pct, 1),
                "mean_impact_kph": _round(self.mean_impact_kph),
                "max_impact_kph": _round(self.max_impact_kph),
                "false_activation_cases": self.false_activation_cases,
                "false_activations": self.false_activations,
                "reaction_brake_median_s": _round(median(self.reaction_brake_s), 3),
                "reaction_half_median_s": _round(median(self.reaction_half_s), 3),
                "lag_brake_median_s": _round(median(self.lag_brake_s), 3),
                "lag_brake_min_s": _round(min(self.lag_brake_s, default=None), 3),
                "shadow_cases": self.shadow_cases}


def _round(x: float | None, digits: int = 1) -> float | None:
    return None if x is None else round(x, digits)


def median(values: Sequence[float]) -> float | None:
    return statistics.median(values) if values else None


def family_scores(cases: Iterable[CaseScore]) -> list[FamilyScore]:
    """Per (family, configuration), in the order first seen."""
    out: dict[tuple[str, str], FamilyScore] = {}
    for c in cases:
        f = out.setdefault((c.family, c.config),
                           FamilyScore(c.family, c.group, c.kind, c.config))
        f.cases += 1
        f.points += c.points
        if c.error:
            f.errors += 1
            continue
        f.passed += c.passed
        f.avoided += c.avoided
        if c.collision:
            f.collisions += 1
            if c.impact_speed_kph is not None:
                f.impact_speeds_kph.append(c.impact_speed_kph)
        if c.false_activations:
            f.false_activation_cases += 1
            f.false_activations += c.false_activations
        for name in ("reaction_brake_s", "reaction_half_s", "lag_brake_s"):
            value = getattr(c, name)
            if value is not None:
                getattr(f, name).append(value)
        if c.shadow is not None and c.shadow.differing:
            f.shadow_cases += 1
    return list(out.values())
