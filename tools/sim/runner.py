"""The closed loop in real time: the simulated world, its radar on CAN, its ground truth
on `sim/world` (the camera plugin renders it), and the actuator's position back into the
ego's brakes. A SIMULATION of the vehicle and its sensors; the stack under test (radar,
camera, fusion, brake services) runs unchanged in its own processes.

One loop thread ticks every few milliseconds: it steps the world with the actuator's
position, writes a radar cycle every 72-76 ms, publishes the world at 50 Hz and records
the run's timeline (the per-tick logic is scenario_run.py's, shared with the lockstep
loop). The radar keeps cycling between runs (an empty road, the ego at
rest), as a real radar never stops: fusion keeps its heartbeat and the brake stays armed.
"""

import logging
import random
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import can
import msgspec

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.keys import BRAKE_STATUS, EGO_MOTION, FUSION_BRAKE_CMD, VEHICLE_DRIVER
from aeb_radar_camera.common.messages import BrakeCommand, BrakeStatus, Header
from aeb_radar_camera.tools.keys import SIM_WORLD
from aeb_radar_camera.tools.sim.radar_feed import RadarFeed
from aeb_radar_camera.tools.sim.scenario import Scenario
from aeb_radar_camera.tools.sim.scenario_run import (
    LoopSettings,
    RadarSchedule,
    ScenarioRun,
    radar_view,
    vehicle_messages,
    world_message,
)
from aeb_radar_camera.tools.sim.verdict import Sample, Verdict
from aeb_radar_camera.tools.sim.world import World

_log = logging.getLogger("sim")


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


@dataclass
class RunResult:
    scenario: Scenario
    verdict: Verdict
    samples: list[Sample] = field(default_factory=list)
    start_mono_ns: int = 0
    end_mono_ns: int = 0


@dataclass
class _Run(ScenarioRun):
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
        self._driver_pub = (bus.publisher(VEHICLE_DRIVER) if self.settings.vehicle_motion
                            else None)
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
        verdict = run.verdict()
        return RunResult(scenario, verdict, run.samples, start, end)

    # -- the loop -----------------------------------------------------------------------

    def _loop(self) -> None:
        s = self.settings
        last = time.monotonic()
        radar = RadarSchedule(s.radar_period_s, self._rng, last)
        next_world = last
        while not self._stop.is_set():
            now = time.monotonic()
            dt = now - last
            last = now
            with self._lock:
                run = self._run
            position = self.actuator.position_pct()
            if run is not None:
                run.step(dt, position)
            if radar.due(now):
                self._radar_cycle(run)
                self.late_ticks = radar.late
            if run is not None and not run.done.is_set():
                self._record(run, position)
            if now >= next_world:
                self._publish_world(run)
                next_world = now + s.world_period_s
            time.sleep(max(0.0, s.tick_s - (time.monotonic() - now)))

    def _radar_cycle(self, run: _Run | None) -> None:
        try:
            self.feed.cycle(*radar_view(run))
        except (OSError, can.CanError) as exc:   # a vanished link must not end the loop
            self.radar_errors += 1
            if self.radar_errors in (1, 10, 100) or self.radar_errors % 1000 == 0:
                _log.error("radar cycle not sent (%d so far): %r", self.radar_errors, exc)

    def _publish_world(self, run: _Run | None) -> None:
        seq = self.bus.next_seq("sim/world")
        stamp, mono = wall_ns(), mono_ns()
        world = world_message(run, Header(seq, "sim", stamp, mono), self._runs)
        self._world_pub.put(world)
        if self._motion_pub is not None and self._driver_pub is not None:
            motion, driver = vehicle_messages(run, Header(0, "sim", stamp, mono))
            self._motion_pub.put(msgspec.structs.replace(motion, header=Header(
                self.bus.next_seq("vehicle/motion"), "sim", stamp, mono)))
            self._driver_pub.put(msgspec.structs.replace(driver, header=Header(
                self.bus.next_seq("vehicle/driver"), "sim", stamp, mono)))

    def _record(self, run: _Run, position: float) -> None:
        sample = run.record(self.decision, self.brake_state, self.actuator.commanded_pct(),
                            position, self.settings)
        if self.on_sample is not None:
            self.on_sample(sample)
        if run.ended:
            run.done.set()

