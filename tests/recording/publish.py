"""A stack's worth of valid messages published at a steady pace (tests of recording,
replay and the Foxglove bridge): camera frames (real 848x480 JPEGs), radar cycles with
their raw CAN batch, fusion targets (a ROI on the frame checked) and commands, brake
status, radar status and camera info."""

import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aeb_radar_camera.common.bus import Bus, TypedPublisher
from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.imaging import encode_jpeg
from aeb_radar_camera.common.keys import (
    BRAKE_STATUS,
    CAMERA_INFO,
    CAMERA_JPEG,
    FUSION_BRAKE_CMD,
    FUSION_TARGETS,
    RADAR_CAN,
    RADAR_STATUS,
    RADAR_TRACKS,
)
from aeb_radar_camera.common.messages import (
    BusState,
    CameraInfo,
    CanFrame,
    CompressedFrame,
    Decision,
    RadarStatus,
    RawCanFrames,
    Verification,
    VerifiedTarget,
)
from tests.system.messages import (
    brake_command,
    brake_status,
    header,
    radar_tracks,
    track,
    verified_targets,
)

WIDTH, HEIGHT = 848, 480


def textured_jpeg(seed: int = 0) -> bytes:
    """A textured 848x480 frame (about 60 KB at quality 80, like the simulator's)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH]
    img = (128 + 60 * np.sin(x / 17.0) * np.cos(y / 23.0)
           + rng.normal(0, 12, (HEIGHT, WIDTH))).clip(0, 255).astype(np.uint8)
    return encode_jpeg(np.dstack([img, img, img]), 80)


@dataclass
class Published:
    counts: dict[str, int] = field(default_factory=dict)

    def add(self, key: str) -> None:
        self.counts[key] = self.counts.get(key, 0) + 1


class StackPublisher:
    """Publishes until stopped (or `cycles` radar cycles): a frame every `frame_s`, a
    radar cycle (tracks, raw CAN, targets, command) every second frame, brake status
    with every command, radar status and camera info every 10 cycles."""

    def __init__(self, bus: Bus, frame_s: float = 1 / 30, cycles: int | None = None) -> None:
        self.bus = bus
        self.frame_s = frame_s
        self.cycles = cycles
        self.jpeg = textured_jpeg()
        self.published = Published()
        self.stop = threading.Event()
        self.pubs: dict[str, TypedPublisher[Any]] = {
            "jpeg": bus.publisher(CAMERA_JPEG, camera="front"),
            "tracks": bus.publisher(RADAR_TRACKS, sensor="front"),
            "can": bus.publisher(RADAR_CAN, bus="radar"),
            "targets": bus.publisher(FUSION_TARGETS, instance="primary"),
            "cmd": bus.publisher(FUSION_BRAKE_CMD, instance="primary"),
            "brake": bus.publisher(BRAKE_STATUS),
            "status": bus.publisher(RADAR_STATUS, sensor="front"),
            "info": bus.publisher(CAMERA_INFO, camera="front"),
        }
        self.thread = threading.Thread(target=self._run, daemon=True)

    def start(self) -> "StackPublisher":
        self.thread.start()
        return self

    def join(self, timeout_s: float) -> None:
        self.thread.join(timeout_s)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(10)

    def _put(self, name: str, msg) -> None:
        pub = self.pubs[name]
        pub.put(msg)
        self.published.add(pub.key)

    def _run(self) -> None:
        i = 0
        last_frame_stamp = 0
        while not self.stop.wait(self.frame_s):
            now = wall_ns()
            self._put("jpeg", CompressedFrame(header=header(i, "camera/front", now, mono_ns()),
                                              camera="front", width=WIDTH, height=HEIGHT,
                                              jpeg=self.jpeg))
            if i % 2 == 1:
                k = i // 2
                decision = Decision.BRAKE if k % 10 >= 5 else Decision.NONE
                mono = mono_ns()
                self._put("tracks", radar_tracks(k, (track(1, 12.0), track(2, 30.0, 2.0,
                                                                          confirmed=False)),
                                                 now, mono))
                self._put("can", RawCanFrames(
                    header(k, "radar/radar", now, mono), "radar", "slcan", "/dev/pts/x",
                    (CanFrame(timestamp_s=1.0 + k, rx_wall_ns=now, rx_mono_ns=mono,
                              arb_id=0x60A, data=bytes([1, 0, 0, 0x10])),)))
                age_ms = (now - last_frame_stamp) / 1e6
                tgt = VerifiedTarget(
                    track_id=1, x_m=12.0, y_m=0.0, range_m=12.0, range_rate_mps=-5.0,
                    in_path=True, verification=Verification.VERIFIED,
                    roi_xywh=(400, 200, 40, 90), density=0.08, ttc_s=2.4, ttc_eff_s=1.4,
                    decision=decision, reason="test", frame_seq=i - 1, frame_age_ms=age_ms,
                    camera="front")
                self._put("cmd", brake_command("primary", k, k, decision, now))
                self._put("targets", verified_targets("primary", k, (tgt,), stamp_ns=now))
                self._put("brake", brake_status(k, stamp_ns=now, mono_ns=mono))
                if k % 10 == 0:
                    self._put("status", radar_status(k // 10, now))
                    self._put("info", camera_info(k // 10, now))
                if self.cycles is not None and k + 1 >= self.cycles:
                    return
            last_frame_stamp = now
            i += 1


def radar_status(seq: int, now: int) -> RadarStatus:
    return RadarStatus(header=header(seq, "radar/front", now), sensor="front", ready=True,
                       not_ready_reason="", bus_state=BusState.ACTIVE, interface="slcan",
                       channel="/dev/pts/x", radar_state=None, firmware="4.30.2",
                       cycle_period_ms=74.0, frames_per_s=300.0, cycles_total=seq,
                       cycles_incomplete=0, bus_reopens=0, rejected={})


def camera_info(seq: int, now: int) -> CameraInfo:
    return CameraInfo(header=header(seq, "camera/front", now), camera="front", width=WIDTH,
                      height=HEIGHT, k=(600.0, 0.0, 424.0, 0.0, 600.0, 240.0, 0.0, 0.0, 1.0),
                      dist=(0.0, 0.0, 0.0, 0.0), r=(0.0, -1.0, 0.0, 0.0, 0.0, -1.0, 1.0, 0.0,
                                                    0.0), t_m=(0.0, 0.0, 0.0), fps=30.0,
                      source="synthetic", frames_published=seq, frames_dropped=0,
                      read_errors=0, healthy=True, status="")
