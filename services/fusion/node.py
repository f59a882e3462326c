"""The fusion I/O shell: frames to the decoder, radar cycles through the core, messages
out. Exactly one BrakeCommand per RadarTracks, published before the targets."""

import logging
import threading
import time
from collections import deque
from typing import Any

import msgspec
import zenoh

from common.bus import Bus
from common.calibration import Calibration
from common.clock import mono_ns, wall_ns
from common.config.fusion import FusionSettings
from common.counters import ReasonCounter
from common.keys import CAMERA_INFO, CAMERA_JPEG, FUSION_BRAKE_CMD, FUSION_TARGETS, RADAR_TRACKS
from common.log import RateLimitedLog, kv
from common.messages import (
    BrakeCommand,
    CameraInfo,
    Decision,
    DecodeError,
    RadarTracks,
    VerifierStatus,
    decode,
)
from services.fusion.camera_check import calibration_differences
from services.fusion.core import CycleResult, FusionCore
from services.fusion.frames import FrameDecoder


class FusionNode:
    def __init__(self, bus: Bus, settings: FusionSettings, core: FusionCore,
                 decoder: FrameDecoder, log: logging.Logger,
                 calibration: Calibration | None = None) -> None:
        self.bus = bus
        self.s = settings
        self.core = core
        self.decoder = decoder
        self.log = log
        self.counters = ReasonCounter()
        self._rl = RateLimitedLog(log)
        self._lock = threading.Lock()
        self._last_radar_seq: int | None = None
        self._decided_ns = 0
        self._proc_us: deque[float] = deque(maxlen=512)
        self._subs: list[zenoh.Subscriber[None]] = []
        self.calibration = calibration
        self._cmd_pub = bus.publisher(FUSION_BRAKE_CMD, instance=settings.instance)
        self._tgt_pub = bus.publisher(FUSION_TARGETS, instance=settings.instance)

    def start(self) -> None:
        self.decoder.start()
        self._subs.append(self.bus.subscribe_raw(CAMERA_JPEG, self.decoder.submit,
                                                 camera=self.s.frames.camera))
        self._subs.append(self.bus.subscribe_raw(RADAR_TRACKS, self._on_tracks,
                                                 sensor=self.s.radar_sensor))
        if self.calibration is not None:
            self._subs.append(self.bus.subscribe(CAMERA_INFO, self.on_camera_info,
                                                 camera=self.s.frames.camera))

    def stop(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        self._subs.clear()
        self.decoder.stop()

    def on_camera_info(self, info: CameraInfo, key: str) -> None:
        """Warn (rate-limited) and count when the camera's calibration is not ours."""
        if self.calibration is None:
            return
        diff = calibration_differences(self.calibration, info)
        if diff:
            self.counters.add("camera_calibration_mismatch")
            self._rl.warning("calibration", "camera_calibration_differs", camera=info.camera,
                             ours=self.s.calibration, differences="; ".join(diff))

    def _on_tracks(self, payload: bytes, key: str, rx_mono_ns: int) -> None:
        self.on_tracks_payload(payload, key, rx_mono_ns)

    def on_tracks_payload(self, payload: bytes, key: str, rx_mono_ns: int) -> CycleResult | None:
        """Zenoh's callback for a radar cycle: decode, decide, publish. Returns what was
        published (None for a payload that is not a RadarTracks)."""
        try:
            tracks = decode(payload, RadarTracks)
        except DecodeError as exc:
            # Not a radar cycle: nothing to answer, but never silent.
            self.counters.add("radar_undecodable")
            self._rl.warning("radar:decode", "radar_tracks_undecodable", key=key, error=exc)
            return None
        return self.handle(tracks, rx_mono_ns)

    def handle(self, tracks: RadarTracks, rx_mono_ns: int) -> CycleResult:
        """Process one cycle: the BrakeCommand is published the moment the core has
        decided it, the targets when every track is done."""
        with self._lock:
            self._check_order(tracks)
            feed = self.decoder.snapshot()
            sent: list[BrakeCommand] = []

            def publish(cmd: BrakeCommand) -> None:
                self._cmd_pub.put(msgspec.structs.replace(
                    cmd, header=msgspec.structs.replace(cmd.header, pub_mono_ns=mono_ns())))
                sent.append(cmd)
                self._decided_ns = mono_ns()

            try:
                result = self.core.process(tracks, feed, wall_ns(), mono_ns(), publish)
            except Exception as exc:  # one command per cycle even when a bug bites
                self.counters.add("processing_error")
                self._rl.error("core", "fusion_cycle_failed", radar_seq=tracks.header.seq,
                               error=repr(exc))
                result = self.core.failed_cycle(tracks, repr(exc), wall_ns(), mono_ns())
                if sent:   # the command went out before the failure: never a second one
                    result = CycleResult(result.targets, sent[0])
                else:
                    publish(result.command)
            processing_ns = self._decided_ns - rx_mono_ns
            targets = msgspec.structs.replace(
                result.targets, processing_ns=processing_ns,
                header=msgspec.structs.replace(result.targets.header, pub_mono_ns=mono_ns()))
            self._tgt_pub.put(targets)
            self._count(result)
            self._proc_us.append(processing_ns / 1e3)
            return CycleResult(targets, result.command)

    def _check_order(self, tracks: RadarTracks) -> None:
        seq = tracks.header.seq
        last = self._last_radar_seq
        if last is not None and seq <= last:
            # Answered all the same (one command per cycle); the stamp decides staleness.
            self.counters.add("radar_seq_not_increasing")
            self._rl.warning("radar:order", "radar_seq_not_increasing", seq=seq, last=last)
        elif last is not None and seq > last + 1:
            self.counters.add("radar_cycles_missed", seq - last - 1)
        self._last_radar_seq = seq

    def _count(self, result: CycleResult) -> None:
        cmd = result.command
        self.counters.add("cycles")
        if cmd.decision is not Decision.NONE:
            self.counters.add(cmd.decision.value.lower() + ("_held" if cmd.held else ""))
        if cmd.verifier_status is not VerifierStatus.OK:
            self.counters.add(cmd.verifier_status.value)
            self._rl.warning(f"status:{cmd.verifier_status.value}", "verifier_not_ok",
                             status=cmd.verifier_status.value,
                             reason=result.targets.unavailable_reason or cmd.reason)

    def stats(self) -> dict[str, Any]:
        feed = self.decoder.snapshot()
        proc = sorted(self._proc_us)
        out: dict[str, Any] = dict(self.counters.snapshot())
        out.update(frames=feed.received, frames_unusable=feed.undecodable,
                   frames_dropped=feed.dropped, invalid_tracks=self.core.invalid_tracks)
        if proc:
            out.update(proc_p50_us=proc[len(proc) // 2], proc_max_us=proc[-1])
        return out

    def log_stats(self) -> None:
        self.log.info(kv("fusion_stats", **self.stats()))


def run_until(stop: threading.Event, node: FusionNode, interval_s: float) -> None:
    """Log statistics every interval until `stop` is set."""
    next_log = time.monotonic() + interval_s
    while not stop.wait(max(0.0, next_log - time.monotonic())):
        node.log_stats()
        next_log += interval_s
