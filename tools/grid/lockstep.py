"""The closed loop in lockstep: one scenario through the services' pure cores in ONE
process on a SIMULATED clock, deterministic for a scenario and a loop seed, much faster
than real time. A SIMULATION of the vehicle, its sensors, its actuator and the links
between the services; the cores are the stack's own.

    result = run_scenario(load_scenario(find_scenario("pedestrian_crossing_20kph")),
                          LoopConfig.load(DEPLOY / "fusion.toml"))
    result.verdict, result.samples, result.cycles

Per tick (tools/sim/scenario_run.py, shared with the real-time runner): the world steps
with the actuator's position, a radar cycle is sent when due (72-76 ms), the timeline
sample is recorded. Between the ticks, in time order with the modelled delays
(delays.py): the radar's CAN frames into the radar service's frame path (radar.py), its
RadarTracks, encoded and decoded as on the wire, into `FusionCore.process` with the
camera's frames as fusion's decoder would hold them (camera.py: 30 fps, each rendered
only when fusion reads it), the signed BrakeCommand into `BrakeCore.on_command`, its
lines to the simulated actuator and the acknowledgements back (brake.py), the brake's
timer at its due times; `vehicle/motion` and `vehicle/driver` every 20 ms (the ego's
speed and yaw rate, the scenario's driver; `LoopSettings.vehicle_motion`) into every
fusion core's vehicle state after a hop. A candidate fusion (`LoopConfig.candidate`) gets the same
tracks and frames in shadow mode: its commands never reach the brake.

Before the scenario starts the loop runs on an empty road until the brake is armed and
fusion says NONE, as `aeb demo` waits for the stack to settle.
"""

import random
import time
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import msgspec

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.command_auth import (
    CommandKey,
    CommandSigner,
    load_signing_key,
    new_key,
)
from aeb_radar_camera.common.config.brake import BrakeSettings
from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import load_config
from aeb_radar_camera.common.config.radar import RadarSettings
from aeb_radar_camera.common.messages import (
    BrakeCommand,
    Decision,
    DriverInputs,
    EgoMotion,
    Header,
    RadarTracks,
    VerifiedTargets,
    decode,
)
from aeb_radar_camera.common.resources import EXAMPLE_CALIBRATION
from aeb_radar_camera.services.brake.core import CoreView
from aeb_radar_camera.services.fusion.core import CycleResult, FusionCore
from aeb_radar_camera.services.fusion.main import build_core
from aeb_radar_camera.services.fusion.verifiers import wants_depth
from aeb_radar_camera.tools.grid.brake import LockstepBrake
from aeb_radar_camera.tools.grid.camera import CameraSettings, LockstepCamera, SceneCamera
from aeb_radar_camera.tools.grid.clock import Events
from aeb_radar_camera.tools.grid.delays import Delays
from aeb_radar_camera.tools.grid.profile import Profile
from aeb_radar_camera.tools.grid.radar import LockstepRadar
from aeb_radar_camera.tools.messages import SimWorld
from aeb_radar_camera.tools.recording.frame_source import FrameSource
from aeb_radar_camera.tools.sim.radar_model import radar_sees
from aeb_radar_camera.tools.sim.radar_reach import radar_for
from aeb_radar_camera.tools.sim.scenario import RadarLook, Scenario
from aeb_radar_camera.tools.sim.scenario_run import (
    LoopSettings,
    RadarSchedule,
    ScenarioRun,
    radar_view,
    vehicle_messages,
    world_message,
)
from aeb_radar_camera.tools.sim.verdict import Sample, Verdict

SETTLE_LIMIT_S = 10.0             # the stack arms within half a second; beyond: broken
SETTLED_POSITION_PCT = 2.0        # the runner's "actuator released"
HOUSEKEEPING_NS = 10_000_000      # the radar service's, while frames flow


IDEAL = "ideal"


class LockstepError(RuntimeError):
    """The loop could not run the scenario (the stack never armed, a config that does
    not fit the simulated camera)."""


@dataclass(frozen=True)
class LoopConfig:
    """The stack's configuration for a run: the followed fusion instance (the brake
    follows it, with its command key), an optional candidate in shadow mode, the radar
    service's settings, the simulated camera's."""

    fusion: FusionConfig
    candidate: FusionConfig | None = None
    radar: RadarSettings = field(default_factory=RadarSettings)
    camera: CameraSettings = field(default_factory=CameraSettings)
    delays: Delays = field(default_factory=Delays)
    loop: LoopSettings = field(default_factory=LoopSettings)
    name: str = ""                # how results name this configuration
    # IDEAL (a bound, not a system): fusion's decision replaced by full braking from the
    # first radar cycle after the ground truth puts the ego on a collision course with an
    # object the radar can see
    ideal: bool = False

    @classmethod
    def load(cls, fusion: Path, candidate: Path | None = None,
             ideal: bool = False) -> "LoopConfig":
        """From fusion config files; the radar's settings are the defaults (the paper's
        prefilter, 25 m), widened to what a kinematic fusion's range gate reaches.
        `ideal`: the IDEAL decision on this loop (named ``ideal``). Raises ConfigError."""
        cfg = load_config(fusion, FusionConfig)
        cand = load_config(candidate, FusionConfig) if candidate is not None else None
        return cls(cfg, cand, radar=radar_for(cfg, cand),
                   name=IDEAL if ideal else fusion.stem, ideal=ideal)


@dataclass
class FusionCycle:
    """One radar cycle as fusion decided it: when (run time), its targets and command,
    the brake's view right after the command (None while it was in flight at the end),
    and the candidate's outputs of the same cycle."""

    t_s: float
    targets: VerifiedTargets
    command: BrakeCommand
    brake: CoreView | None = None
    candidate: CycleResult | None = None


@dataclass
class LockstepResult:
    scenario: Scenario
    config: str
    verdict: Verdict
    samples: list[Sample]
    cycles: list[FusionCycle]
    loop_seed: int
    settle_s: float                     # the empty road before the scenario started
    wall_s: float                       # how long the run took on this host
    cpu_s: float                        # the process's CPU time for it (all its threads)
    profile: Profile
    fusion_failures: int = 0            # cycles whose processing raised (answered
    candidate_failures: int = 0         # as the shell answers them)

    @property
    def simulated_s(self) -> float:
        return self.samples[-1].t_s if self.samples else 0.0

    @property
    def first_brake_t_s(self) -> float | None:
        return self.verdict.first_brake_t_s


def followed_key(cfg: FusionConfig) -> CommandKey:
    """The key the followed instance signs with and the brake accepts: its
    `command_key`, or - a shadow config, unsigned in its file - a key made for this
    simulated run, so that any fusion config can be the one the brake follows. Raises
    KeyFileError."""
    s = cfg.fusion
    if not s.command_key:
        return new_key(s.instance)
    return load_signing_key(s.command_key, s.instance)


class _Fusion:
    """One fusion instance: its core, its signer (None: shadow, never signed)."""

    def __init__(self, cfg: FusionConfig, key: CommandKey | None, session: int) -> None:
        self.cfg = cfg
        self.core: FusionCore = build_core(cfg)[0]
        self.cameras = [c.name for c in cfg.fusion.camera_inputs]
        self.signer = CommandSigner(key, session) if key is not None else None
        self.failures = 0

    def process(self, tracks: RadarTracks, frames: FrameSource, wall_ns: int,
                mono_ns: int) -> CycleResult:
        """The cycle's outputs; a cycle whose processing raises is answered as the shell
        answers it (counted)."""
        feeds = [frames.feed(c, mono_ns) for c in self.cameras]
        try:
            return self.core.process(tracks, feeds, wall_ns, mono_ns)
        except Exception as exc:
            self.failures += 1
            return self.core.failed_cycle(tracks, repr(exc), wall_ns, mono_ns)


class Lockstep:
    """One run's loop. `scenes`: the simulated camera's renderer (one per process)."""

    def __init__(self, scenario: Scenario, config: LoopConfig, scenes: SceneCamera,
                 loop_seed: int = 0) -> None:
        self.scenario = scenario
        self.config = config
        self.loop_seed = loop_seed
        self.events = ev = Events()
        self.profile = Profile()
        self.delays = d = config.delays
        self.rng = random.Random(f"{scenario.name}/{scenario.seed}/{loop_seed}")
        s = config.fusion.fusion
        _check_camera(config.fusion, config.camera)
        if config.candidate is not None:
            _check_camera(config.candidate, config.camera)
        key = followed_key(config.fusion)
        self.primary = _Fusion(config.fusion, key, self.rng.getrandbits(63))
        self.candidate = (_Fusion(config.candidate, None, 0)
                          if config.candidate is not None else None)
        depth = any(wants_depth(f.core.verifier) for f in self._instances())
        self.frames = FrameSource({config.camera.name: (scenes.cal.width, scenes.cal.height)})
        self.camera = LockstepCamera(scenes, self.frames, config.camera, depth, self.profile)
        self.scenes = scenes
        self.radar = LockstepRadar(ev, config.radar, d, RadarLook(), 0)
        keys = {key.key_id: key}
        self.brake = LockstepBrake(ev, BrakeSettings(instance=s.instance,
                                                     command_keys=(s.command_key,)), keys, d)
        self.schedule = RadarSchedule(config.loop.radar_period_s, self.rng, 0.0)
        self.run: ScenarioRun | None = None
        self.scene = 0                  # the camera's scene number of the run
        self.decision = ""              # the followed instance's latest command
        self.start_ns: int | None = None   # the tick the run started at
        self._starting = False
        self.cycles: list[FusionCycle] = []
        self._tick_ns = round(config.loop.tick_s * 1e9)
        self._world_ns = 0              # when the world was last stepped
        self._ideal_braking = False     # IDEAL: a collision course has been seen

    def _instances(self) -> list[_Fusion]:
        return [self.primary] + ([self.candidate] if self.candidate is not None else [])

    # -- the run --------------------------------------------------------------------------

    def execute(self) -> tuple[ScenarioRun, float]:
        """Settle on the empty road, then play the scenario to its end; the run and the
        settling time. Raises LockstepError when the stack never armed."""
        ev = self.events
        try:
            self.brake.connect(0)
            ev.at(0, self._tick)
            ev.at(round(self.rng.uniform(0, self.camera.period_ns)), self._capture)
            ev.at(HOUSEKEEPING_NS, self._housekeeping)
            if self.config.loop.vehicle_motion:
                ev.at(0, self._vehicle)
            if not ev.run_until(self._settled, round(SETTLE_LIMIT_S * 1e9)):
                raise LockstepError(
                    f"{self.scenario.name}: the stack did not settle within "
                    f"{SETTLE_LIMIT_S:g} s (fusion {self.decision or 'silent'}, brake "
                    f"{self.brake.core.state.value}: {self.brake.core.reason})")
            self._starting = True         # at the next tick
            limit = ev.now_ns + round((self.scenario.duration_s + 1.0) * 1e9)
            ev.run_until(lambda: self.run is not None and self.run.ended, limit)
        finally:
            self.brake.close()
        assert self.run is not None and self.start_ns is not None
        return self.run, self.start_ns / 1e9

    def _settled(self) -> bool:
        view = self.brake.view
        return (self.run is None and self.decision == "NONE"
                and self.brake.core.state.value == "ARMED"
                and self.brake.position_pct(self.events.now_ns) <= SETTLED_POSITION_PCT
                and view.commanded_pct() == 0.0)

    def _run_time_s(self, t_ns: int) -> float:
        return (t_ns - self.start_ns) / 1e9 if self.start_ns is not None else 0.0

    # -- events -----------------------------------------------------------------------------

    def _tick(self, t_ns: int) -> None:
        with self.profile.part("world"):
            position = self.brake.position_pct(t_ns)
            self.brake.step(t_ns)
            run = self.run
            if run is not None:
                run.step(self.config.loop.tick_s, position)
            self._world_ns = t_ns
        if self.schedule.due(t_ns / 1e9):
            with self.profile.part("radar"):
                published = self.radar.cycle(*radar_view(run), t_ns)
            for at, payload in published:
                self.events.at(at + self.delays.zenoh_hop_ns,
                               partial(self._fusion, payload))
        if run is not None and not run.ended:
            with self.profile.part("world"):
                run.record(self.decision, self.brake.core.state.value,
                           self.brake.view.commanded_pct(), position, self.config.loop)
        if self._starting:
            self._start(t_ns)
        if run is None or not run.ended:
            self.events.at(t_ns + self._tick_ns, self._tick)

    def _start(self, t_ns: int) -> None:
        """The scenario from this tick on (its first step is the next tick's)."""
        self._starting = False
        self.scene = self.scenes.scene()
        self.radar.reset(self.scenario.radar, self.scenario.seed)
        self.run = ScenarioRun.start(self.scenario, self.scene)
        self.start_ns = t_ns

    def _housekeeping(self, t_ns: int) -> None:
        with self.profile.part("radar"):
            published = self.radar.tick(t_ns)
        for at, payload in published:
            self.events.at(at + self.delays.zenoh_hop_ns, partial(self._fusion, payload))
        self.events.at(t_ns + HOUSEKEEPING_NS, self._housekeeping)

    def _vehicle(self, t_ns: int) -> None:
        """The vehicle gateway's tick: both messages, as of the last world step, to every
        fusion core one hop later."""
        ev = self.events
        header = Header(seq=0, source="sim", stamp_ns=ev.wall_ns(t_ns),
                        pub_mono_ns=ev.mono_ns(t_ns))
        messages = vehicle_messages(self.run, header)
        ev.at(t_ns + self.delays.zenoh_hop_ns, partial(self._vehicle_arrives, messages))
        ev.at(t_ns + round(self.config.loop.world_period_s * 1e9), self._vehicle)

    def _vehicle_arrives(self, messages: tuple[EgoMotion, DriverInputs], t_ns: int) -> None:
        wall, mono = self.events.wall_ns(t_ns), self.events.mono_ns(t_ns)
        for fusion in self._instances():
            for msg in messages:
                fusion.core.on_vehicle(msg, wall, mono)

    def _world(self, t_ns: int) -> SimWorld:
        header = Header(seq=0, source="sim", stamp_ns=self.events.wall_ns(t_ns),
                        pub_mono_ns=self.events.mono_ns(t_ns))
        return world_message(self.run, header, self.scene)

    def _capture(self, t_ns: int) -> None:
        # The world as of the last tick (the camera extrapolates it to the capture time).
        self.camera.capture(self._world(self._world_ns), self.events.wall_ns(t_ns),
                            self.events.mono_ns(t_ns + self.delays.camera_frame_ns))
        self.events.at(t_ns + self.camera.period_ns, self._capture)

    def _fusion(self, payload: bytes, t_ns: int) -> None:
        ev = self.events
        tracks = decode(payload, RadarTracks)
        wall, mono = ev.wall_ns(t_ns), ev.mono_ns(t_ns)
        with self.profile.part("fusion"):
            result = self.primary.process(tracks, self.frames, wall, mono)
            shadow = (self.candidate.process(tracks, self.frames, wall, mono)
                      if self.candidate is not None else None)
        published = t_ns + self.delays.fusion_ns
        command = self._ideal(result.command) if self.config.ideal else result.command
        command = _published(command, ev.mono_ns(published))
        signer = self.primary.signer
        assert signer is not None
        signed = signer.sign(command)
        cycle: FusionCycle | None = None
        if self.run is not None and not self.run.ended:
            cycle = FusionCycle(self._run_time_s(t_ns), result.targets, command,
                                candidate=shadow)
            self.cycles.append(cycle)
        ev.at(published + self.delays.zenoh_hop_ns,
              partial(self._brake_command, signed, command.decision, cycle))

    def _ideal(self, command: BrakeCommand) -> BrakeCommand:
        """IDEAL: fusion's command replaced by full braking, held to the end, from the
        first cycle whose latest tick had the ground truth on a collision course (at
        current velocities) with an object the radar can see (in its field of view, not
        hidden behind a parked car: a decision cannot brake for what no sensor has
        seen), else by a NONE. No confirmation, no camera: with the loop's radar cycle,
        delays and actuator unchanged, the impact speeds it leaves are what no decision
        on this loop can beat."""
        run = self.run
        if not self._ideal_braking and run is not None and not run.ended and run.samples:
            threat = run.world.threat()
            if threat is not None and radar_sees(run.world.vehicle_bodies(),
                                                 threat.object_index):
                self._ideal_braking = True
        if self._ideal_braking:
            return msgspec.structs.replace(
                command, decision=Decision.BRAKE, brake_level_pct=100.0, held=False,
                reason="ideal: the ground truth's collision course")
        return msgspec.structs.replace(command, decision=Decision.NONE, brake_level_pct=0.0,
                                       held=False, reason="ideal: no collision course")

    def _brake_command(self, payload: bytes, decision: Decision, cycle: FusionCycle | None,
                       t_ns: int) -> None:
        self.decision = decision.value
        with self.profile.part("brake"):
            view = self.brake.on_command(payload, t_ns)
        if cycle is not None:
            cycle.brake = view


def _published(command: BrakeCommand, pub_mono_ns: int) -> BrakeCommand:
    """The command as the shell publishes it: stamped when it was decided."""
    return msgspec.structs.replace(
        command, header=msgspec.structs.replace(command.header, pub_mono_ns=pub_mono_ns))


def _check_camera(cfg: FusionConfig, camera: CameraSettings) -> None:
    names = [c.name for c in cfg.fusion.camera_inputs]
    if names != [camera.name]:
        raise LockstepError(f"fusion {cfg.fusion.instance} verifies with cameras {names}; the "
                            f"simulated camera is {camera.name!r} alone")


def run_scenario(scenario: Scenario, config: LoopConfig, scenes: SceneCamera | None = None,
                 loop_seed: int = 0) -> LockstepResult:
    """Play one scenario in lockstep and judge it. `scenes`: the simulated camera's
    renderer (built here when not given: a second or two); `loop_seed`: the loop's own
    draws (radar cycle lengths, the camera's phase) - the scenario's seed drives the
    world's and the radar model's. Raises LockstepError, ConfigError, KeyFileError."""
    t0, cpu0 = time.perf_counter(), time.process_time()
    scenes = scenes or SceneCamera(Calibration.load(EXAMPLE_CALIBRATION))
    loop = Lockstep(scenario, config, scenes, loop_seed)
    run, settle_s = loop.execute()
    return LockstepResult(
        scenario=scenario, config=config.name or config.fusion.fusion.instance,
        verdict=run.verdict(), samples=run.samples, cycles=loop.cycles, loop_seed=loop_seed,
        settle_s=settle_s, wall_s=time.perf_counter() - t0,
        cpu_s=time.process_time() - cpu0, profile=loop.profile,
        fusion_failures=loop.primary.failures,
        candidate_failures=loop.candidate.failures if loop.candidate is not None else 0)
