"""One scenario run tick by tick, whatever clock drives it: the world stepped with the
actuator's position, when the radar's next cycle is due, the timeline sample of each
tick, when the run ends, and the world as `sim/world` carries it to the camera. A
SIMULATION of the vehicle and its surroundings.

One implementation for both loops: the real-time runner (runner.py: the stack in its own
processes, ticks on the monotonic clock) and the lockstep loop (tools/grid/lockstep.py:
the services' cores in one process, ticks on a simulated clock).
"""

import math
import random
from dataclasses import dataclass, field

from aeb_radar_camera.common.messages import DriverInputs, EgoMotion, Gear, Header
from aeb_radar_camera.tools.messages import SimObject, SimWorld
from aeb_radar_camera.tools.sim.scenario import Scenario, ScenarioKind
from aeb_radar_camera.tools.sim.verdict import Sample, Verdict, judge
from aeb_radar_camera.tools.sim.world import Body, World

STOPPED_MPS = 0.01
# The simulated car's steering (the world keeps the lane; the wheel angle is what a
# driver would turn for the road's curvature): a bicycle model.
SIM_WHEELBASE_M = 2.7
SIM_STEERING_RATIO = 15.0


@dataclass(frozen=True)
class LoopSettings:
    tick_s: float = 0.005
    world_period_s: float = 0.02       # sim/world and vehicle/motion at 50 Hz
    stopped_hold_s: float = 1.0        # a run ends after the ego stood still this long
    passed_margin_m: float = 5.0       # ... or drove this far past every object
    radar_period_s: tuple[float, float] = (0.072, 0.076)
    vehicle_motion: bool = True        # also publish vehicle/motion (ego speed, yaw rate)


class RadarSchedule:
    """When the simulated radar's cycles fall: every 72-76 ms (`period_s`), drawn from
    `rng`. A loop that fell behind (a loaded machine) sends one cycle, not a burst, and
    counts it in `late`."""

    def __init__(self, period_s: tuple[float, float], rng: random.Random,
                 start_s: float) -> None:
        self.period_s = period_s
        self.rng = rng
        self.next_s = start_s
        self.late = 0

    def due(self, now_s: float) -> bool:
        """Whether a cycle is due at `now_s` (and if so, the next one is scheduled)."""
        if now_s < self.next_s:
            return False
        self.next_s += self.rng.uniform(*self.period_s)
        if self.next_s < now_s:
            self.next_s = now_s + self.period_s[0]
            self.late += 1
        return True


@dataclass
class ScenarioRun:
    """A scenario in motion: its world, its timeline, whether it has ended. `number`
    counts the runs of one loop (the camera starts a new scene at each)."""

    scenario: Scenario
    world: World
    number: int
    samples: list[Sample] = field(default_factory=list)
    stopped_since_s: float | None = None
    ended: bool = False

    @classmethod
    def start(cls, scenario: Scenario, number: int) -> "ScenarioRun":
        return cls(scenario, World(scenario), number)

    def step(self, dt_s: float, position_pct: float) -> None:
        """The world `dt_s` on with the actuator at `position_pct` (nothing once ended)."""
        if not self.ended:
            self.world.step(dt_s, position_pct)

    def record(self, decision: str, brake_state: str, commanded_pct: float,
               position_pct: float, settings: LoopSettings) -> Sample:
        """This tick's sample (appended to the timeline), and whether the run ended with
        it: a collision, the scenario's duration, the ego stopped for `stopped_hold_s`,
        or (no threat) past every object."""
        w = self.world
        threat = w.threat()
        gap = w.in_path_gap()
        sample = Sample(w.t_s, w.ego.s_m, w.ego.speed_mps,
                        gap if gap is not None else (threat.gap_m if threat else None),
                        threat.ttc_s if threat else None, decision, brake_state,
                        commanded_pct, position_pct, w.false_target_gap())
        self.samples.append(sample)
        if w.ego.speed_mps <= STOPPED_MPS:
            if self.stopped_since_s is None:
                self.stopped_since_s = w.t_s
        else:
            self.stopped_since_s = None
        self.ended = (w.collision is not None or w.t_s >= self.scenario.duration_s
                      or (self.stopped_since_s is not None
                          and w.t_s - self.stopped_since_s >= settings.stopped_hold_s)
                      or (self.scenario.kind is ScenarioKind.NO_THREAT
                          and w.passed_everything(settings.passed_margin_m)))
        return sample

    def verdict(self) -> Verdict:
        """The run's verdict (verdict.judge). Raises ValueError before the first sample."""
        return judge(self.scenario.name, self.scenario.kind, self.samples,
                     self.world.collision)


def radar_view(run: ScenarioRun | None) -> tuple[list[Body], float, float, float]:
    """What the radar sees this cycle: the bodies in the vehicle frame (so the radar's x
    is 0), the ego's speed and yaw rate; the empty road with the ego at rest between runs
    (a real radar never stops cycling)."""
    if run is None or run.ended:
        return [], 0.0, 0.0, 0.0
    w = run.world
    return w.vehicle_bodies(), 0.0, w.ego.speed_mps, w.yaw_rate_dps()


def world_message(run: ScenarioRun | None, header: Header, runs: int) -> SimWorld:
    """`sim/world` now: the run's world (`active` until it ended), or, between runs
    (`runs` so far), the empty road with the ego at rest."""
    if run is None:
        return SimWorld(header=header, scenario="", run=runs, active=False, t_s=0.0,
                        ego_x_m=0.0, ego_speed_mps=0.0, ego_accel_mps2=0.0, gap_m=None,
                        ttc_s=None, objects=(), seed=0, brightness=1.0, noise=2.0)
    w = run.world
    threat = w.threat()
    objects: tuple[SimObject, ...] = tuple(w.bodies())
    speed, yaw_rate, pose = w.ego.speed_mps, w.yaw_rate_dps(), w.ego_pose()
    return SimWorld(
        header=header, scenario=run.scenario.name, run=run.number, active=not run.ended,
        t_s=w.t_s, ego_x_m=pose.x_m, ego_speed_mps=speed,
        ego_accel_mps2=-w.ego.decel_mps2 if speed > 0 else 0.0,
        gap_m=threat.gap_m if threat else None, ttc_s=threat.ttc_s if threat else None,
        objects=objects, seed=run.scenario.seed,
        brightness=run.scenario.camera.brightness, noise=run.scenario.camera.noise,
        ego_y_m=pose.y_m, ego_heading_deg=math.degrees(pose.heading_rad),
        ego_yaw_rate_dps=yaw_rate, ego_s_m=w.ego.s_m, ego_d_m=w.ego.d_m,
        road=run.scenario.road, lighting=run.scenario.lighting)


def vehicle_messages(run: ScenarioRun | None, header: Header) -> tuple[EgoMotion, DriverInputs]:
    """`vehicle/motion` and `vehicle/driver` now, as the gateway would publish them: the
    ego's speed and yaw rate, the driver's inputs from the scenario's `[driver]` (the
    ego at rest, nothing pressed, between runs)."""
    if run is None or run.ended:
        motion = EgoMotion(header=header, speed_mps=0.0, yaw_rate_dps=0.0)
        return motion, DriverInputs(
            header=header, steering_wheel_angle_deg=0.0, steering_wheel_rate_dps=0.0,
            accelerator_pedal_pct=0.0, kickdown=False, brake_pedal_pressed=False,
            brake_pressure_bar=0.0, gear=Gear.DRIVE)
    w = run.world
    d = run.scenario.driver
    t = w.t_s
    k = w.road.curvature_at(w.ego.s_m)
    angle = math.degrees(math.atan(SIM_WHEELBASE_M * k)) * SIM_STEERING_RATIO
    rate = 0.0
    if d.steer_at_s is not None and t >= d.steer_at_s:
        turning = t - d.steer_at_s
        angle += d.steer_rate_dps * min(turning, d.steer_duration_s)
        rate = d.steer_rate_dps if turning < d.steer_duration_s else 0.0
        # A lane change ends with the wheel turned back as fast, over its last part.
        back = turning - (d.lane_change_s - d.steer_duration_s)
        if d.lane_change_m and back > 0.0:
            angle -= d.steer_rate_dps * min(back, d.steer_duration_s)
            rate = -d.steer_rate_dps if back < d.steer_duration_s else 0.0
    kickdown = d.kickdown_at_s is not None and t >= d.kickdown_at_s
    braking = d.brake_at_s is not None and t >= d.brake_at_s
    motion = EgoMotion(header=header, speed_mps=w.ego.speed_mps, yaw_rate_dps=w.yaw_rate_dps())
    return motion, DriverInputs(
        header=header, steering_wheel_angle_deg=angle, steering_wheel_rate_dps=rate,
        accelerator_pedal_pct=100.0 if kickdown else 0.0 if braking else d.accelerator_pct,
        kickdown=kickdown, brake_pedal_pressed=braking,
        brake_pressure_bar=30.0 if braking else 0.0, gear=Gear.DRIVE)
