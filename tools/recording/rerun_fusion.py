"""Fusion's pure core over a recording, offline: no Zenoh, no clock of its own.

Every radar cycle of the recording goes through `FusionCore.decide` and `report` in the
recorded order, with the recorded time, and with the camera frames the live instance
had. What the recording says about them, and so how exact the re-run is:

- the time: the live core's `now` is the radar stamp plus the recorded `radar_age_ms`
  (what its VerifiedTargets say); without a recorded output, the recorder's receive time;
- the frames: the frames live fusion held are not published, but its VerifiedTargets
  name the frame each track was checked in (`frame_seq`). The re-run's ring is the
  recorded frames up to that one (at most the live ring's size), less any that would have
  been nearer to the cycle than it (the live ring cannot have held them, or it would have
  chosen them). Without a frame named (no recorded output, no track checked), the ring is
  the frames the recorder had received before the cycle, made to agree with what the
  recorded cycle says of the camera: when it had no usable frame, less those the cycle
  would have used (they had not reached fusion yet); when it had one and the recorder
  had none in time, with the next frames the recorder received (they reached fusion
  first). Live fusion may still have held other frames (decoding lag, frames dropped on
  its link): the comparison then shows it, typically as another `unavailable_reason`;
- the depth: live fusion pairs a frame with its depth only once the depth has arrived
  and been decoded, so a frame checked just as its depth came may have had none. Where
  the recorded output says whether the frame it was checked in had depth (the
  `depth_available` of a verifier's gate detail), the re-run's frame has it or not as
  live; elsewhere a frame has the depth the recorder had received by the cycle. A
  frame that had depth live whose depth is not in the recording is counted
  (`depth_missing`) and said: its cycles may differ;
- with several cameras, each camera's frame is named only for the tracks it decided.

The rings and their counters are fusion's decoder's as tools/recording/frame_source.py
keeps them: frames are decoded only when the core reads a selected frame's pixels (a
cycle that gates nothing decodes nothing); a recorded frame that does not decode fails
its cycle as the live shell fails one (counted) and is left out after that. The outputs
are deterministic: the same recording and configuration give the same bytes.
"""

from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import msgspec

from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.keys import (
    CAMERA_DEPTH,
    CAMERA_JPEG,
    EGO_MOTION,
    FUSION_BRAKE_CMD,
    FUSION_TARGETS,
    RADAR_TRACKS,
    VEHICLE_DRIVER,
)
from aeb_radar_camera.common.messages import (
    BrakeCommand,
    DecodeError,
    DriverInputs,
    EgoMotion,
    RadarTracks,
    VerifiedTargets,
    VerifierStatus,
    decode,
)
from aeb_radar_camera.common.vehicle_state import VehicleState
from aeb_radar_camera.services.fusion.core import CycleResult
from aeb_radar_camera.services.fusion.frames import DecodedFrame, FrameFeed, select_frame
from aeb_radar_camera.services.fusion.main import build_core
from aeb_radar_camera.tools.recording.frame_source import FrameSource, SourcedFrame
from aeb_radar_camera.tools.recording.reader import Record, Recording

# A cycle is re-run once the recording is this far past it: its frames and recorded
# outputs have arrived by then (the recorder gets them from separate subscriptions).
LOOKAHEAD_NS = 1_000_000_000
_EARLY_KEPT = 64


@dataclass
class Cycle:
    """One radar cycle of the recording, its recorded outputs, and the re-run's."""

    tracks: RadarTracks
    log_ns: int
    recorded_cmd: BrakeCommand | None = None
    recorded: VerifiedTargets | None = None
    recorded_log_ns: int | None = None
    result: CycleResult | None = None


@dataclass
class RerunStats:
    cycles: int = 0
    frames_in_recording: int = 0
    frames_decoded: int = 0
    frames_undecodable: int = 0
    frames_pinned: int = 0        # cycles whose frame was named by the recorded output
    depth_pinned: int = 0         # frames whose depth followed the recorded output
    depth_missing: int = 0        # ... of which had depth live that is not recorded
    failed_cycles: int = 0        # the core raised: answered as the shell does
    undecodable: dict[str, int] = field(default_factory=dict)
    first_log_ns: int | None = None
    last_log_ns: int | None = None


class FusionRerun:
    """`cfg`: the configuration to re-run with (the recorded instance's, or a changed
    one); `instance`: whose recorded outputs to pin frames and time to and compare with
    (default: the config's)."""

    def __init__(self, cfg: FusionConfig, instance: str | None = None,
                 vehicle: str = "ego") -> None:
        self.cfg = cfg
        self.s = cfg.fusion
        self.instance = instance or self.s.instance
        self.vehicle = vehicle
        core, cals = build_core(cfg)
        self.core = core
        self.sizes = {name: (cal.width, cal.height) for name, cal in cals.items()}
        self.cameras = [c.name for c in self.s.camera_inputs]
        self.stats = RerunStats()
        self.frames = FrameSource(self.sizes, self.stats.undecodable)
        self._early: dict[tuple[int, int], tuple[BrakeCommand | None, VerifiedTargets | None,
                                                 int | None]] = {}
        self._skew_ns = round(self.s.frames.max_skew_s * 1e9)
        self._tracks_topic = RADAR_TRACKS.key(vehicle, sensor=self.s.radar_sensor)
        self._cmd_topic = FUSION_BRAKE_CMD.key(vehicle, instance=self.instance)
        self._targets_topic = FUSION_TARGETS.key(vehicle, instance=self.instance)
        self._frame_topics = {CAMERA_JPEG.key(vehicle, camera=c): c for c in self.cameras}
        self._depth_topics = {CAMERA_DEPTH.key(vehicle, camera=c): c for c in self.cameras}
        # vehicle/motion and vehicle/driver as recorded, applied in log time before each
        # cycle, fresh or not as the live instance found them (its recorded output): the
        # kinematic rule re-run on the state the live instance had.
        self._vehicle_topics: dict[str, type] = {EGO_MOTION.key(vehicle): EgoMotion,
                                                 VEHICLE_DRIVER.key(vehicle): DriverInputs}
        vs = self.s.vehicle_state
        self._vehicle = VehicleState(vs.stamp_check, vs.max_age_s)
        self._vehicle_queue: deque[tuple[int, EgoMotion | DriverInputs]] = deque()

    @property
    def topics(self) -> list[str]:
        return [self._tracks_topic, self._cmd_topic, self._targets_topic,
                *self._frame_topics, *self._depth_topics, *self._vehicle_topics]

    def run(self, recording: Recording, start_ns: int | None = None,
            end_ns: int | None = None) -> Iterator[Cycle]:
        """Every cycle re-run, in recorded order."""
        pending: deque[Cycle] = deque()
        by_cycle: dict[tuple[int, int], Cycle] = {}
        for rec in recording.records(self.topics, start_ns, end_ns):
            st = self.stats
            st.first_log_ns = rec.log_time_ns if st.first_log_ns is None else st.first_log_ns
            st.last_log_ns = rec.log_time_ns
            self._take(rec, pending, by_cycle)
            while pending and pending[0].log_ns < rec.log_time_ns - LOOKAHEAD_NS:
                yield self._rerun(pending.popleft(), by_cycle)
        while pending:
            yield self._rerun(pending.popleft(), by_cycle)

    def _take(self, rec: Record, pending: deque[Cycle],
              by_cycle: dict[tuple[int, int], Cycle]) -> None:
        topic = rec.topic
        camera = self._frame_topics.get(topic)
        try:
            if topic in self._vehicle_topics:
                msg: EgoMotion | DriverInputs = (
                    decode(rec.data, EgoMotion) if self._vehicle_topics[topic] is EgoMotion
                    else decode(rec.data, DriverInputs))
                self._vehicle_queue.append((rec.log_time_ns, msg))
            elif topic in self._depth_topics:
                self.frames.add_depth(self._depth_topics[topic], rec.data, rec.log_time_ns)
            elif camera is not None:
                self.stats.frames_in_recording += 1
                self.frames.add_recorded(camera, rec.data, rec.log_time_ns)
            elif topic == self._tracks_topic:
                tracks = decode(rec.data, RadarTracks)
                cycle = Cycle(tracks, rec.log_time_ns)
                key = (tracks.header.seq, tracks.header.stamp_ns)
                pending.append(cycle)
                by_cycle[key] = cycle
                # Outputs the recorder received before the cycle itself (its threads
                # take each key's samples separately).
                early = self._early.pop(key, None)
                if early is not None:
                    cycle.recorded_cmd, cycle.recorded, cycle.recorded_log_ns = early
            elif topic == self._cmd_topic:
                cmd = decode(rec.data, BrakeCommand)
                key = (cmd.radar_seq, cmd.header.stamp_ns)
                found = by_cycle.get(key)
                if found is not None:
                    found.recorded_cmd = cmd
                else:
                    self._keep_early(key, rec.log_time_ns, cmd=cmd)
            elif topic == self._targets_topic:
                targets = decode(rec.data, VerifiedTargets)
                key = (targets.radar_seq, targets.header.stamp_ns)
                found = by_cycle.get(key)
                if found is not None:
                    found.recorded = targets
                    found.recorded_log_ns = rec.log_time_ns
                else:
                    self._keep_early(key, rec.log_time_ns, targets=targets)
        except DecodeError:
            self.stats.undecodable[topic] = self.stats.undecodable.get(topic, 0) + 1

    def _keep_early(self, key: tuple[int, int], log_ns: int, cmd: BrakeCommand | None = None,
                    targets: VerifiedTargets | None = None) -> None:
        old_cmd, old_targets, old_log = self._early.get(key, (None, None, None))
        self._early[key] = (cmd or old_cmd, targets or old_targets,
                            log_ns if targets is not None else old_log)
        while len(self._early) > _EARLY_KEPT:     # outputs of cycles never recorded
            del self._early[next(iter(self._early))]

    def _rerun(self, cycle: Cycle, by_cycle: dict[tuple[int, int], Cycle]) -> Cycle:
        tracks = cycle.tracks
        del by_cycle[(tracks.header.seq, tracks.header.stamp_ns)]
        recorded = cycle.recorded
        if recorded is not None and recorded.radar_age_ms is not None:
            now_wall = tracks.header.stamp_ns + round(recorded.radar_age_ms * 1e6)
        else:
            now_wall = cycle.log_ns
        now_mono = (cycle.recorded_cmd.header.pub_mono_ns if cycle.recorded_cmd is not None
                    else cycle.log_ns)
        feeds = [self._feed(c, tracks.header.stamp_ns, cycle) for c in self.cameras]
        q = self._vehicle_queue
        while q and q[0][0] <= cycle.log_ns:
            log_ns, msg = q.popleft()
            if isinstance(msg, EgoMotion):
                self._vehicle.motion.observe(msg, log_ns, log_ns)
            else:
                self._vehicle.driver.observe(msg, log_ns, log_ns)
        live = cycle.recorded
        if live is not None and (live.vehicle_state or live.ego_speed_mps is not None):
            # the live instance's verdict on the vehicle state, as its frame is pinned
            vehicle = self._vehicle.sample_as(live.vehicle_state, cycle.log_ns)
        else:
            vehicle = self._vehicle.sample(cycle.log_ns)
        try:
            decided = self.core.decide(tracks, feeds, now_wall, now_mono, vehicle)
            targets = self.core.report(decided)
            result = CycleResult(targets, decided.command)
        except Exception as exc:  # answered as the live shell answers a failing cycle
            self.stats.failed_cycles += 1
            result = self.core.failed_cycle(tracks, repr(exc), now_wall, now_mono)
        self.stats.cycles += 1
        self.stats.frames_decoded = self.frames.decoded
        self.stats.frames_undecodable = self.frames.decode_failed
        cycle.result = result
        return cycle

    def _pinned_seq(self, camera: str, recorded: VerifiedTargets | None) -> int | None:
        if recorded is None:
            return None
        single = len(self.cameras) == 1
        for t in recorded.targets:
            if t.frame_seq is not None and (t.camera == camera or (single and not t.camera)):
                return t.frame_seq
        return None

    def _feed(self, camera: str, radar_stamp_ns: int, cycle: Cycle) -> FrameFeed:
        frames = self.frames.window(camera)
        pinned = self._pinned_seq(camera, cycle.recorded)
        chosen = next((f for f in frames if f.seq == pinned), None)
        if chosen is not None:
            self.stats.frames_pinned += 1
            gap = abs(chosen.stamp_ns - radar_stamp_ns)
            ring = self.frames.ring(f for f in frames if f.seq <= chosen.seq and (
                f is chosen or abs(f.stamp_ns - radar_stamp_ns) > gap))
        else:
            ring = self.frames.ring(self.frames.received_by(camera, cycle.log_ns))
        recorded = cycle.recorded
        if pinned is None and recorded is not None:
            ring = self._as_recorded(camera, ring, frames, cycle, recorded)
        return self.frames.feed(camera, cycle.log_ns, ring,
                                self._depth_pins(camera, frames, recorded))

    def _depth_pins(self, camera: str, frames: tuple[SourcedFrame, ...],
                    recorded: VerifiedTargets | None) -> dict[int, bool]:
        """Capture stamp -> whether live fusion had the frame's depth, for the frames
        the recorded output says it of (counted; and counted missing when it had depth
        the recording does not hold)."""
        if recorded is None:
            return {}
        single = len(self.cameras) == 1
        stamps = {f.seq: f.stamp_ns for f in frames}
        pins: dict[int, bool] = {}
        for t in recorded.targets:
            had = t.gate_detail.get("depth_available")
            stamp = stamps.get(t.frame_seq) if t.frame_seq is not None else None
            if had is None or stamp is None or stamp in pins or not (
                    t.camera == camera or (single and not t.camera)):
                continue
            pins[stamp] = bool(had)
            self.stats.depth_pinned += 1
            if had and not self.frames.depth.has(camera, stamp):
                self.stats.depth_missing += 1
        return pins

    def _as_recorded(self, camera: str, ring: tuple[SourcedFrame, ...],
                     frames: tuple[SourcedFrame, ...], cycle: Cycle,
                     recorded: VerifiedTargets) -> tuple[SourcedFrame, ...]:
        """A ring that agrees with what the recorded cycle says of the camera, where no
        frame is named: none usable (those the recorder had in time had not reached
        fusion yet), or one usable (it reached fusion before it reached the recorder)."""
        stamp = cycle.tracks.header.stamp_ns

        def usable(ring: tuple[SourcedFrame, ...]) -> DecodedFrame | None:
            return select_frame(ring, stamp, self._skew_ns, self.s.frames.align)

        if camera in recorded.cameras_unavailable:
            while (late := usable(ring)) is not None:
                ring = tuple(f for f in ring if f is not late)
        elif recorded.verifier_status is VerifierStatus.OK and usable(ring) is None:
            for later in (f for f in frames if f.rx_mono_ns > cycle.log_ns):
                ring = self.frames.ring((*ring, later))
                if usable(ring) is not None:
                    break
        return ring


def normalised(result: CycleResult) -> CycleResult:
    """The outputs with the fields only a live shell fills (processing time) set as
    the re-run has them: zero."""
    return CycleResult(msgspec.structs.replace(result.targets, processing_ns=0),
                       result.command)


def config_params(cfg: FusionConfig) -> dict[str, Any]:
    """What distinguishes a configuration, for the re-run's metadata."""
    s = cfg.fusion
    return {"instance": s.instance, "verifier": s.verifier.name,
            "verifier_params": dict(s.verifier.params),
            "decision": msgspec.to_builtins(s.decision),
            "frames": msgspec.to_builtins(s.frames)}
