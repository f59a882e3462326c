"""The fusion I/O shell: each camera's frames (and, for a verifier that needs depth, its
depth) to its decoder, radar cycles through the core, messages out. Exactly one
BrakeCommand per radar cycle handled, published before its VerifiedTargets; from the bus,
at most one cycle per `min_cycle_interval_s` (`RadarGate`), the newest: a flood of tracks
sheds cycles instead of signing a command for each."""

import logging
import threading
import time
from collections import deque
from collections.abc import Mapping, Sequence
from typing import Any

import msgspec
import zenoh

from aeb_radar_camera.common import systemd
from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.command_auth import CommandSigner
from aeb_radar_camera.common.config.fusion import FusionSettings, RuleName
from aeb_radar_camera.common.counters import ReasonCounter
from aeb_radar_camera.common.keys import (
    CAMERA_DEPTH,
    CAMERA_INFO,
    CAMERA_JPEG,
    EGO_MOTION,
    FUSION_BRAKE_CMD,
    FUSION_TARGETS,
    RADAR_TRACKS,
    VEHICLE_DRIVER,
)
from aeb_radar_camera.common.log import RateLimitedLog, kv
from aeb_radar_camera.common.messages import (
    CameraInfo,
    Decision,
    DecodeError,
    DriverInputs,
    EgoMotion,
    RadarTracks,
    VerifierStatus,
    decode,
)
from aeb_radar_camera.common.realtime import ThreadRealtime
from aeb_radar_camera.common.systemd import Watchdog
from aeb_radar_camera.services.fusion.camera_check import calibration_differences
from aeb_radar_camera.services.fusion.core import CycleResult, DecidedCycle, FusionCore
from aeb_radar_camera.services.fusion.frames import FROZEN_REASON, FrameDecoder
from aeb_radar_camera.services.fusion.verifiers import wants_depth

RADAR_RING = 4     # radar samples Zenoh keeps for the radar thread; the oldest dropped


# A radar sequence step larger than this (cycles; about 70 s at 14 Hz) is a jump, not
# that many missed cycles.
MAX_RADAR_SEQ_GAP = 1000


class RadarGate:
    """At most one radar cycle per `interval_ns`: `wait_ns` says how long until the next
    may be handled, `take` marks one handled. Not thread-safe: the radar thread only."""

    def __init__(self, interval_ns: int) -> None:
        self.interval_ns = interval_ns
        self._last_ns: int | None = None

    def wait_ns(self, now_ns: int) -> int:
        if self._last_ns is None:
            return 0
        return max(0, self._last_ns + self.interval_ns - now_ns)

    def take(self, now_ns: int) -> None:
        self._last_ns = now_ns


class LocalRing:
    """What Zenoh's RingChannel handler offers (`recv`, `try_recv`), filled by a
    callback: for a bus without a Zenoh session (test doubles)."""

    def __init__(self, capacity: int) -> None:
        self._items: deque[tuple[bytes, str, int]] = deque(maxlen=capacity)
        self._cond = threading.Condition()
        self._closed = False

    def put(self, payload: bytes, key: str, rx_mono_ns: int) -> None:
        with self._cond:
            self._items.append((payload, key, rx_mono_ns))
            self._cond.notify()

    def recv(self) -> tuple[bytes, str, int]:
        """The oldest item, waiting for one. Raises EOFError once closed."""
        with self._cond:
            while not self._items and not self._closed:
                self._cond.wait()
            if not self._items:
                raise EOFError("closed")
            return self._items.popleft()

    def try_recv(self) -> tuple[bytes, str, int] | None:
        with self._cond:
            return self._items.popleft() if self._items else None

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()


class FusionShell:
    """`decoders`: one per camera, in the core's camera order (one FrameDecoder for a
    single camera). `calibrations`: what each camera's CameraInfo is checked against.
    `signer`: signs every BrakeCommand (None: published unsigned)."""

    def __init__(self, bus: Bus, settings: FusionSettings, core: FusionCore,
                 decoders: FrameDecoder | Sequence[FrameDecoder], log: logging.Logger,
                 calibrations: Calibration | Mapping[str, Calibration] | None = None,
                 signer: CommandSigner | None = None) -> None:
        self.bus = bus
        self.s = settings
        self.core = core
        self.decoders = ([decoders] if isinstance(decoders, FrameDecoder) else list(decoders))
        if len(self.decoders) != len(core.cameras):
            raise ValueError(f"{len(self.decoders)} decoders for {len(core.cameras)} cameras")
        self.camera_names = [c.name for c in core.cameras]
        self.signer = signer
        self.log = log
        self.counters = ReasonCounter()
        self._rl = RateLimitedLog(log)
        self._lock = threading.Lock()
        # The core's vehicle state: written by the vehicle subscriptions, sampled once per
        # radar cycle (a lock of its own: a 50 Hz sample never waits for a radar cycle).
        self._vehicle_lock = threading.Lock()
        self._last_radar_seq: int | None = None
        self._proc_us: deque[float] = deque(maxlen=512)
        self._subs: list[zenoh.Subscriber[None]] = []
        if isinstance(calibrations, Calibration):
            calibrations = {self.camera_names[0]: calibrations}
        self.calibrations: dict[str, Calibration] = dict(calibrations or {})
        self._cmd_pub = bus.publisher(FUSION_BRAKE_CMD, instance=settings.instance)
        self._tgt_pub = bus.publisher(FUSION_TARGETS, instance=settings.instance)
        self._rt = ThreadRealtime(settings.realtime, log, "fusion radar callback")
        self._gate = RadarGate(round(settings.min_cycle_interval_s * 1e9))
        self.tracks_shed = 0
        self._radar_sub: Any = None
        self._local_ring: LocalRing | None = None
        self._radar_thread: threading.Thread | None = None

    @property
    def decoder(self) -> FrameDecoder:
        """The first camera's decoder (the only one in a single-camera instance)."""
        return self.decoders[0]

    def start(self) -> None:
        for name, decoder in zip(self.camera_names, self.decoders, strict=True):
            decoder.start()
            self._subs.append(self.bus.subscribe_raw(CAMERA_JPEG, decoder.submit, camera=name))
            if wants_depth(self.core.verifier):
                self._subs.append(self.bus.subscribe_raw(CAMERA_DEPTH, decoder.submit_depth,
                                                         camera=name))
        self._start_radar()
        if self.s.decision.rule is RuleName.KINEMATIC:
            self._subs.append(self.bus.subscribe(EGO_MOTION, self.on_vehicle))
            self._subs.append(self.bus.subscribe(VEHICLE_DRIVER, self.on_vehicle))
        for name in self.camera_names:
            if name in self.calibrations:
                self._subs.append(self.bus.subscribe(CAMERA_INFO, self.on_camera_info,
                                                     camera=name))

    def stop(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        self._subs.clear()
        if self._radar_sub is not None:
            self._radar_sub.undeclare()       # ends the radar thread's wait
            self._radar_sub = None
        if self._local_ring is not None:
            self._local_ring.close()
        if self._radar_thread is not None:
            self._radar_thread.join(timeout=5.0)
        for decoder in self.decoders:
            decoder.stop()

    def on_camera_info(self, info: CameraInfo, key: str) -> None:
        """Warn (rate-limited) and count when the camera's calibration is not ours."""
        ours = self.calibrations.get(info.camera)
        if ours is None:
            return
        diff = calibration_differences(ours, info)
        if diff:
            self.counters.add("camera_calibration_mismatch")
            self._rl.warning(f"calibration:{info.camera}", "camera_calibration_differs",
                             camera=info.camera, ours=ours.origin,
                             differences="; ".join(diff))

    def on_vehicle(self, msg: EgoMotion | DriverInputs, key: str) -> None:
        """`vehicle/motion` or `vehicle/driver` (any thread) into the core's state."""
        with self._vehicle_lock:
            self.core.on_vehicle(msg, wall_ns(), mono_ns())

    def _start_radar(self) -> None:
        """Radar cycles reach the radar thread through a ring that Zenoh fills without
        running any Python, the oldest dropped: a flood of tracks costs fusion only the
        cycles it decides (a bus double without a session: a ring of our own)."""
        session = getattr(self.bus, "session", None)
        handler: Any
        if isinstance(session, zenoh.Session):
            self._radar_sub = session.declare_subscriber(
                RADAR_TRACKS.wildcard(self.bus.vehicle, sensor=self.s.radar_sensor),
                zenoh.handlers.RingChannel(RADAR_RING))
            handler = self._radar_sub.handler
        else:
            ring = self._local_ring = LocalRing(RADAR_RING)
            self._subs.append(self.bus.subscribe_raw(RADAR_TRACKS, ring.put,
                                                     sensor=self.s.radar_sensor))
            handler = ring
        self._radar_thread = threading.Thread(target=self._radar_loop, args=(handler,),
                                              name="fusion-radar", daemon=True)
        self._radar_thread.start()

    def _radar_loop(self, handler: Any) -> None:
        """One radar cycle at a time: the newest waiting, at most one per
        `min_cycle_interval_s`; the older ones waiting are shed (`tracks_shed`)."""
        self._rt.ensure()
        while True:
            try:
                item = handler.recv()
                wait = self._gate.wait_ns(mono_ns())
                if wait > 0:
                    time.sleep(wait / 1e9)
                while (newer := handler.try_recv()) is not None:
                    item = newer
                    self._shed()
            except (zenoh.ZError, EOFError):
                return                       # undeclared: fusion is stopping
            if not isinstance(item, tuple) and item.kind != zenoh.SampleKind.PUT:
                continue
            self._gate.take(mono_ns())
            payload, key, rx = self._unpack(item)
            tracks = self._decoded(payload, key)
            if tracks is not None:
                try:
                    self.handle(tracks, rx)
                except Exception as exc:  # the radar thread must outlive a bug
                    self.counters.add("processing_error")
                    self._rl.error("radar", "radar_cycle_failed", error=repr(exc))

    def _shed(self) -> None:
        """Count a cycle left out for a newer one (those the ring itself dropped are not
        seen: `tracks_shed` is a lower bound under a flood)."""
        self.tracks_shed += 1
        self._rl.warning("radar:shed", "radar_cycles_shed", shed=self.tracks_shed,
                         min_cycle_interval_s=self.s.min_cycle_interval_s,
                         detail="tracks faster than one cycle per interval: the newest is "
                                "decided, the others shed")

    @staticmethod
    def _unpack(item: Any) -> tuple[bytes, str, int]:
        """(payload, key, receipt) of a ring item (a Zenoh sample: received now)."""
        if isinstance(item, tuple):
            return item
        return item.payload.to_bytes(), str(item.key_expr), mono_ns()

    def _decoded(self, payload: bytes, key: str) -> RadarTracks | None:
        try:
            return decode(payload, RadarTracks)
        except DecodeError as exc:
            # Not a radar cycle: nothing to answer, but never silent.
            self.counters.add("radar_undecodable")
            self._rl.warning("radar:decode", "radar_tracks_undecodable", key=key, error=exc)
            return None

    def on_tracks_payload(self, payload: bytes, key: str, rx_mono_ns: int) -> CycleResult | None:
        """A radar cycle's payload handled at once (no gate): decode, decide, publish.
        Returns what was published (None for a payload that is not a RadarTracks)."""
        tracks = self._decoded(payload, key)
        return None if tracks is None else self.handle(tracks, rx_mono_ns)

    def handle(self, tracks: RadarTracks, rx_mono_ns: int) -> CycleResult:
        """Process one cycle: its BrakeCommand is published as soon as it is decided, then
        its VerifiedTargets."""
        with self._lock:
            self._check_order(tracks)
            feeds = [d.snapshot() for d in self.decoders]
            decided: DecidedCycle | None = None
            with self._vehicle_lock:
                now_mono = mono_ns()
                vehicle = self.core.vehicle.sample(now_mono)
            try:
                decided = self.core.decide(tracks, feeds, wall_ns(), now_mono, vehicle)
                command = decided.command
            except Exception as exc:  # one command per radar cycle, even when a bug bites
                self._count_failure(tracks, exc)
                failed = self.core.failed_cycle(tracks, repr(exc), wall_ns(), mono_ns())
                command = failed.command
            # Processing ends where the command is handed to Zenoh: the put itself belongs
            # to the hop, as the radar's put does.
            decided_ns = mono_ns()
            command = msgspec.structs.replace(
                command, header=msgspec.structs.replace(command.header, pub_mono_ns=decided_ns))
            if self.signer is None:
                self._cmd_pub.put(command)
            else:
                self._cmd_pub.put_bytes(self.signer.sign(command))
            if decided is None:
                targets = failed.targets
            else:
                try:
                    targets = self.core.report(decided)
                except Exception as exc:  # the command is out; the report says what failed
                    self._count_failure(tracks, exc)
                    targets = self.core.failed_report(tracks, command, repr(exc), wall_ns(),
                                                      mono_ns())
            processing_ns = decided_ns - rx_mono_ns
            targets = msgspec.structs.replace(
                targets, processing_ns=processing_ns,
                header=msgspec.structs.replace(targets.header, pub_mono_ns=mono_ns()))
            self._tgt_pub.put(targets)
            result = CycleResult(targets, command)
            self._count(result)
            self._proc_us.append(processing_ns / 1e3)
        return result

    def _count_failure(self, tracks: RadarTracks, exc: Exception) -> None:
        self.counters.add("processing_error")
        self._rl.error("core", "fusion_cycle_failed", radar_seq=tracks.header.seq,
                       error=repr(exc))

    def _check_order(self, tracks: RadarTracks) -> None:
        seq = tracks.header.seq
        last = self._last_radar_seq
        if last is not None and seq <= last:
            # Answered all the same (one command per cycle); the stamp decides staleness.
            self.counters.add("radar_seq_not_increasing")
            self._rl.warning("radar:order", "radar_seq_not_increasing", seq=seq, last=last)
        elif last is not None and seq > last + MAX_RADAR_SEQ_GAP:
            # Not cycles lost (a forged or flooded sample, a radar host's counter reset
            # upwards): counted as a jump, so that the missed count keeps its meaning.
            self.counters.add("radar_seq_jumps")
            self._rl.warning("radar:order", "radar_seq_jump", seq=seq, last=last)
        elif last is not None and seq > last + 1:
            self.counters.add("radar_cycles_missed", seq - last - 1)
        self._last_radar_seq = seq

    def _count(self, result: CycleResult) -> None:
        cmd = result.command
        self.counters.add("cycles")
        for camera, why in result.targets.cameras_unavailable.items():
            if why == FROZEN_REASON:
                self.counters.add("camera_frozen")
                self._rl.warning(f"frozen:{camera}", "camera_frozen", camera=camera,
                                 cycles=self.core.frozen_cycles.get(camera, 0),
                                 detail="the same picture while the radar sees the scene "
                                        "move: camera unavailable")
        if cmd.decision is not Decision.NONE:
            self.counters.add(cmd.decision.value.lower() + ("_held" if cmd.held else ""))
        if result.targets.vehicle_state:
            # The degraded mode (docs/fusion.md): at most WARNING until the state is fresh.
            self.counters.add("vehicle_state_stale")
            self._rl.warning("vehicle:stale", "vehicle_state_stale",
                             detail=result.targets.vehicle_state,
                             policy="kinematic rule at most WARNING")
        if cmd.override:
            self.counters.add("driver_override")
            self.counters.add("override_" + cmd.override.replace(" ", "_").replace("-", ""))
        if cmd.verifier_status is not VerifierStatus.OK:
            self.counters.add(cmd.verifier_status.value)
            self._rl.warning(f"status:{cmd.verifier_status.value}", "verifier_not_ok",
                             status=cmd.verifier_status.value,
                             reason=result.targets.unavailable_reason or cmd.reason)

    def stats(self) -> dict[str, Any]:
        feeds = [d.snapshot() for d in self.decoders]
        proc = sorted(self._proc_us)
        out: dict[str, Any] = dict(self.counters.snapshot())
        out.update(frames=sum(f.received for f in feeds),
                   frames_unusable=sum(f.undecodable for f in feeds),
                   frames_dropped=sum(f.dropped for f in feeds),
                   frames_corrupt=sum(f.corrupt for f in feeds),
                   depth_received=sum(f.depth_received for f in feeds),
                   depth_unusable=sum(f.depth_undecodable + f.depth_dropped for f in feeds),
                   invalid_tracks=self.core.invalid_tracks, tracks_shed=self.tracks_shed,
                   beside_path_targets=self.core.beside_path_targets,
                   road_edge_targets=self.core.road_edge_targets)
        if self.s.decision.rule is RuleName.KINEMATIC:
            with self._vehicle_lock:
                for name, state in (("motion", self.core.vehicle.motion),
                                    ("driver", self.core.vehicle.driver)):
                    for why, n in state.counts.snapshot().items():
                        out[f"vehicle_{name}_{why}"] = n
        if len(feeds) > 1:
            for name, f in zip(self.camera_names, feeds, strict=True):
                out[f"frames_{name}"] = f"{f.received}/{f.undecodable}/{f.dropped}"
        if proc:
            out.update(proc_p50_us=proc[len(proc) // 2], proc_max_us=proc[-1])
        return out

    def log_stats(self) -> None:
        self.log.info(kv("fusion_stats", **self.stats()))

    def run(self, stop: threading.Event, watchdog: Watchdog | None = None) -> int:
        """Serve until `stop` is set, after `start`: the health token and systemd's ready,
        then statistics every `stats_interval_s` (feeding systemd's watchdog); on the way
        out the token is withdrawn, the subscriptions and decoders stopped and the last
        statistics logged."""
        wait = (watchdog or Watchdog(env={})).wait
        token = self.bus.declare_health("fusion", self.s.instance)
        try:
            systemd.ready(f"serving fusion {self.s.instance}")
            next_log = time.monotonic() + self.s.stats_interval_s
            while not wait(stop, max(0.0, next_log - time.monotonic())):
                self.log_stats()
                next_log += self.s.stats_interval_s
        finally:
            token.undeclare()
            self.stop()
            self.log_stats()
        return 0
