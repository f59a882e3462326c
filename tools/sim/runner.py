"""The closed loop in real time: the simulated world, its radar on CAN, its ground truth
on `sim/world` (the camera plugin renders it), and the actuator's position back into the
ego's brakes. A SIMULATION of the vehicle and its sensors; the stack under test (radar,
camera, fusion, brake services) runs unchanged in its own processes.

One loop thread ticks every few milliseconds: it steps the world with the actuator's
position, writes a radar cycle every 72-76 ms, publishes the world at 50 Hz and records
the run's timeline. The radar keeps cycling between runs (an empty road, the ego at
rest), as a real radar never stops: fusion keeps its heartbeat and the brake stays armed.
"""

import logging
import math
import random
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import can

from common.bus import Bus
from common.clock import mono_ns, wall_ns
from common.keys import BRAKE_STATUS, EGO_MOTION, FUSION_BRAKE_CMD
from common.messages import BrakeCommand, BrakeStatus, EgoMotion, Header
from tools.keys import SIM_WORLD
from tools.messages import SimObject, SimWorld
from tools.sim.radar_feed import RadarFeed
from tools.sim.scenario import Scenario, ScenarioKind
from tools.sim.verdict import Sample, Verdict, judge
from tools.sim.world import World

_log = logging.getLogger("sim")
STOPPED_MPS = 0.01


class Actuator(Protocol):
    """What the loop needs from the (simulated) actuator."""

    def position_pct(self) -> float: ...
    def commanded_pct(self) -> float: ...


class SimActuatorView:
    """The brake engineer's simulated actuator (tools/sim/actuator.py), read
    in-process: its first-order position and the level of the last command it got (kept
    from its event listener: the loop asks every tick)."""

    def __init__(self, actuator: Any) -> None:
        self.actuator = actuator
        self._commanded = 0.0
        actuator.add_listener(self._on_event)

    def _on_event(self, event: Any) -> None:
        if event.cmd is not None:
            self._commanded = float(event.cmd.level_pct)

    def position_pct(self) -> float:
        return float(self.actuator.position_pct())

    def commanded_pct(self) -> float:
        return self._commanded


@dataclass(frozen=True)
class LoopSettings:
    tick_s: float = 0.005
    world_period_s: float = 0.02       # sim/world and vehicle/motion at 50 Hz
    stopped_hold_s: float = 1.0        # a run ends after the ego stood still this long
    passed_margin_m: float = 5.0       # ... or drove this far past every object
    radar_period_s: tuple[float, float] = (0.072, 0.076)
    vehicle_motion: bool = True        # also publish vehicle/motion (ego speed, yaw rate)


@dataclass
class RunResult:
    scenario: Scenario
    verdict: Verdict
    samples: list[Sample] = field(default_factory=list)
    start_mono_ns: int = 0
    end_mono_ns: int = 0


@dataclass
class _Run:
    scenario: Scenario
    world: World
    number: int
    samples: list[Sample] = field(default_factory=list)
    stopped_since: float | None = None
    done: threading.Event = field(default_factory=threading.Event)


class Simulator:
    """Owns the loop thread. `start()`, then `run(scenario)` as often as needed, `stop()`."""

    def __init__(self, bus: Bus, feed: RadarFeed, actuator: Actuator, instance: str = "primary",
                 settings: LoopSettings | None = None, seed: int = 0) -> None:
        self.bus = bus
        self.feed = feed
        self.actuator = actuator
        self.instance = instance
        self.settings = settings or LoopSettings()
        self._rng = random.Random(seed)
        self._lock = threading.Lock()
        self._run: _Run | None = None
        self._runs = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="sim-loop", daemon=True)
        self.decision = ""
        self.brake_state = ""
        self.last_command: BrakeCommand | None = None
        self.last_status: BrakeStatus | None = None
        self.radar_errors = 0
        self.late_ticks = 0
        self.on_sample: Callable[[Sample], None] | None = None
        self._world_pub = bus.publisher(SIM_WORLD)
        self._motion_pub = bus.publisher(EGO_MOTION) if self.settings.vehicle_motion else None
        self._subs = [bus.subscribe(FUSION_BRAKE_CMD, self._on_command, instance=instance),
                      bus.subscribe(BRAKE_STATUS, self._on_status)]

    # -- inputs from the stack ------------------------------------------------------------

    def _on_command(self, msg: BrakeCommand, key: str) -> None:
        self.last_command = msg
        self.decision = msg.decision.value

    def _on_status(self, msg: BrakeStatus, key: str) -> None:
        self.last_status = msg
        self.brake_state = msg.state.value

    # -- life cycle ---------------------------------------------------------------------

    def start(self) -> "Simulator":
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(5.0)

    def settled(self, max_position_pct: float = 2.0) -> bool:
        """The stack is idle: fusion says NONE, the brake is armed, the actuator released."""
        return (self.decision == "NONE" and self.brake_state == "ARMED"
                and self.actuator.position_pct() <= max_position_pct
                and self.actuator.commanded_pct() == 0.0)

    def wait_settled(self, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not self._stop.is_set():
            if self.settled():
                return True
            time.sleep(0.05)
        return self.settled()

    def run(self, scenario: Scenario, timeout_s: float | None = None) -> RunResult:
        """Play one scenario to its end; returns the timeline and the verdict."""
        with self._lock:
            self._runs += 1
            self.feed.reset(scenario.radar_look(), scenario.seed)
            run = _Run(scenario, World(scenario), self._runs)
            self._run = run
            start = mono_ns()
        limit = (timeout_s or scenario.duration_s + 10.0)
        finished = run.done.wait(limit)
        with self._lock:
            self._run = None
            end = mono_ns()
        if not finished and timeout_s is None:
            _log.warning("run %s did not end within %.0f s", scenario.name, limit)
        elif not finished:   # the caller's time limit (e.g. a benchmark's measuring time)
            _log.info("run %s cut at the caller's limit of %.1f s", scenario.name, limit)
        verdict = judge(scenario.name, scenario.kind, run.samples, run.world.collision)
        return RunResult(scenario, verdict, run.samples, start, end)

    # -- the loop -----------------------------------------------------------------------

    def _loop(self) -> None:
        s = self.settings
        last = time.monotonic()
        next_radar = last
        next_world = last
        while not self._stop.is_set():
            now = time.monotonic()
            dt = now - last
            last = now
            with self._lock:
                run = self._run
            position = self.actuator.position_pct()
            if run is not None and not run.done.is_set():
                run.world.step(dt, position)
            if now >= next_radar:
                self._radar_cycle(run)
                next_radar += self._rng.uniform(*s.radar_period_s)
                if next_radar < now:        # fell behind (loaded machine): no burst
                    next_radar = now + s.radar_period_s[0]
                    self.late_ticks += 1
            if run is not None and not run.done.is_set():
                self._record(run, position, now)
            if now >= next_world:
                self._publish_world(run)
                next_world = now + s.world_period_s
            time.sleep(max(0.0, s.tick_s - (time.monotonic() - now)))

    def _radar_cycle(self, run: _Run | None) -> None:
        if run is None or run.done.is_set():
            bodies, speed, yaw_rate = [], 0.0, 0.0
        else:
            w = run.world
            bodies, speed, yaw_rate = w.vehicle_bodies(), w.ego.speed_mps, w.yaw_rate_dps()
        try:
            self.feed.cycle(bodies, 0.0, speed, yaw_rate)
        except (OSError, can.CanError) as exc:   # a vanished link must not end the loop
            self.radar_errors += 1
            if self.radar_errors in (1, 10, 100) or self.radar_errors % 1000 == 0:
                _log.error("radar cycle not sent (%d so far): %r", self.radar_errors, exc)

    def _publish_world(self, run: _Run | None) -> None:
        seq = self.bus.next_seq("sim/world")
        stamp, mono = wall_ns(), mono_ns()
        if run is None:
            world = SimWorld(header=Header(seq, "sim", stamp, mono), scenario="", run=self._runs,
                             active=False, t_s=0.0, ego_x_m=0.0, ego_speed_mps=0.0,
                             ego_accel_mps2=0.0, gap_m=None, ttc_s=None, objects=(), seed=0,
                             brightness=1.0, noise=2.0)
            speed = yaw_rate = 0.0
        else:
            w = run.world
            threat = w.threat()
            objects: tuple[SimObject, ...] = tuple(w.bodies())
            speed, yaw_rate, pose = w.ego.speed_mps, w.yaw_rate_dps(), w.ego_pose()
            world = SimWorld(
                header=Header(seq, "sim", stamp, mono), scenario=run.scenario.name,
                run=run.number, active=not run.done.is_set(), t_s=w.t_s, ego_x_m=pose.x_m,
                ego_speed_mps=speed, ego_accel_mps2=-w.ego.decel_mps2 if speed > 0 else 0.0,
                gap_m=threat.gap_m if threat else None, ttc_s=threat.ttc_s if threat else None,
                objects=objects, seed=run.scenario.seed,
                brightness=run.scenario.camera.brightness, noise=run.scenario.camera.noise,
                ego_y_m=pose.y_m, ego_heading_deg=math.degrees(pose.heading_rad),
                ego_yaw_rate_dps=yaw_rate, ego_s_m=w.ego.s_m, ego_d_m=w.ego.d_m,
                road=run.scenario.road, lighting=run.scenario.lighting)
        self._world_pub.put(world)
        if self._motion_pub is not None:
            self._motion_pub.put(EgoMotion(header=Header(self.bus.next_seq("vehicle/motion"),
                                                         "sim", stamp, mono),
                                           speed_mps=speed, yaw_rate_dps=yaw_rate))

    def _record(self, run: _Run, position: float, now: float) -> None:
        w = run.world
        threat = w.threat()
        gap = w.in_path_gap()
        sample = Sample(w.t_s, w.ego.s_m, w.ego.speed_mps,
                        gap if gap is not None else (threat.gap_m if threat else None),
                        threat.ttc_s if threat else None,
                        self.decision, self.brake_state, self.actuator.commanded_pct(), position,
                        w.false_target_gap())
        run.samples.append(sample)
        if self.on_sample is not None:
            self.on_sample(sample)
        s = self.settings
        if w.ego.speed_mps <= STOPPED_MPS:
            run.stopped_since = run.stopped_since if run.stopped_since is not None else now
        else:
            run.stopped_since = None
        ended = (w.collision is not None or w.t_s >= run.scenario.duration_s
                 or (run.stopped_since is not None and now - run.stopped_since >= s.stopped_hold_s)
                 or (run.scenario.kind is ScenarioKind.NO_THREAT
                     and w.passed_everything(s.passed_margin_m)))
        if ended:
            run.done.set()

