"""Camera and fusion as separate processes with a Zenoh router.

The camera service plays an image folder (a rendered road scene with a box 8 m ahead);
this test plays the radar (RadarTracks) and, for the corrupt-frame case, publishes a
broken JPEG straight onto the camera's key so that fusion receives it like any frame.
"""

import signal
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest

from aeb_radar_camera.common.clock import wall_ns
from aeb_radar_camera.common.imaging import decode_gray, encode_jpeg
from aeb_radar_camera.common.keys import CAMERA_JPEG, FUSION_BRAKE_CMD, FUSION_TARGETS, RADAR_TRACKS
from aeb_radar_camera.common.messages import (
    BrakeCommand,
    CompressedFrame,
    Decision,
    Header,
    Verification,
    VerifiedTargets,
    VerifierStatus,
)
from aeb_radar_camera.services.fusion.roi import Roi
from aeb_radar_camera.tools.sim.rig import rig_calibration_toml
from aeb_radar_camera.tools.sim.scenes import Obstacle, Scene, render
from tests.camera.helpers import folder_config
from tests.fusion.helpers import CAL, CALIBRATION, cycle, track
from tests.support import Collector, HealthWatch, ServiceProcess, open_bus, python_module, wait_for

pytestmark = pytest.mark.slow

INSTANCE = "proc"
BOX = (8.0, 0.8)            # the box in the images
ROAD = (6.0, -0.5)          # plain asphalt in the images


def write_inputs(tmp: Path, endpoint: str) -> tuple[Path, Path]:
    frames = tmp / "frames"
    frames.mkdir()
    scene = render(CAL, Scene(obstacles=(Obstacle(*BOX),), seed=4))
    for i in range(2):
        cv2.imwrite(str(frames / f"f{i}.png"), scene)
    camera = folder_config(tmp / "camera.toml", endpoint, frames, extra="jpeg_quality = 80")
    fusion = tmp / "fusion.toml"
    fusion.write_text(f"""
[zenoh]
connect = ["{endpoint}"]
[fusion]
instance = "{INSTANCE}"
calibration = "{CALIBRATION}"
stats_interval_s = 1.0
# Generous bounds: a loaded CI machine may delay a frame or a cycle by a few hundred ms,
# and this test is about the chain, not the bounds (tests/fusion/test_decision.py).
[fusion.frames]
max_skew_s = 0.5
# the folder plays one still picture while the box moves: a frozen camera by that check
# (tests/fusion/test_frozen_camera.py), which this chain test leaves out
frozen_after_s = 0.0
[fusion.decision]
hold_s = 1.5
radar_max_age_s = 1.0
""")
    return camera, fusion


class Radar:
    """Plays the radar: one RadarTracks per call, answered by exactly one command."""

    def __init__(self, bus, commands: Collector, targets: Collector) -> None:
        self.pub = bus.publisher(RADAR_TRACKS, sensor="front")
        self.commands = commands
        self.targets = targets
        self.seq = 0

    def cycle(self, *tracks, age_ns: int = 0) -> tuple[BrakeCommand, VerifiedTargets]:
        seq = self.seq
        self.seq += 1
        self.pub.put(cycle(*tracks, seq=seq, stamp_ns=wall_ns() - age_ns,
                           last_frame_mono_ns=1_000 + seq))
        cmd = self.commands.wait_until(lambda m: m.radar_seq == seq, 30)
        tgt = self.targets.wait_until(lambda m: m.radar_seq == seq, 30)
        return cmd, tgt


class FrameLog:
    """Every camera frame seen on the bus, by sequence number."""

    def __init__(self) -> None:
        self.by_seq: dict[int, CompressedFrame] = {}
        self._lock = threading.Lock()

    def __call__(self, msg: CompressedFrame, key: str) -> None:
        with self._lock:
            self.by_seq[msg.header.seq] = msg

    def get(self, seq: int) -> CompressedFrame:
        with self._lock:
            return self.by_seq[seq]


def broken_frame(seq: int) -> CompressedFrame:
    jpeg = encode_jpeg(np.zeros((480, 848, 3), np.uint8), 80)
    return CompressedFrame(header=Header(seq=seq, source="test", stamp_ns=wall_ns(),
                                         pub_mono_ns=0),
                           camera="front", width=848, height=480, jpeg=jpeg[: len(jpeg) // 3])


def test_camera_and_fusion_processes_verify_decide_and_survive_a_corrupt_frame(router, tmp_path):
    camera_cfg, fusion_cfg = write_inputs(tmp_path, router)
    with open_bus(router) as bus:
        watch = HealthWatch(bus)
        commands, targets, frames = Collector(), Collector(), FrameLog()
        bus.subscribe(FUSION_BRAKE_CMD, commands, instance=INSTANCE)
        bus.subscribe(FUSION_TARGETS, targets, instance=INSTANCE)
        bus.subscribe(CAMERA_JPEG, frames, camera="front")
        camera = ServiceProcess("camera", python_module("aeb_radar_camera.services.camera", "-c",
                                                        str(camera_cfg)), tmp_path)
        fusion = ServiceProcess("fusion", python_module("aeb_radar_camera.services.fusion", "-c",
                                                        str(fusion_cfg)), tmp_path)
        try:
            watch.wait_alive("camera", "front")
            watch.wait_alive("fusion", INSTANCE)
            radar = Radar(bus, commands, targets)

            # Heartbeats until fusion has decoded a frame near the cycle.
            wait_for(lambda: radar.cycle()[1].verifier_status is VerifierStatus.OK, 60,
                     interval_s=0.05, what="verifier OK")

            # A box 8 m ahead closing at 5 m/s (TTC_eff 0.6 s) and plain road 6 m ahead.
            cmd, tgt = radar.cycle(track(1, *BOX, vx=-5.0), track(2, *ROAD, vx=-5.0))
            assert cmd.decision is Decision.BRAKE and cmd.track_id == 1
            assert cmd.brake_level_pct == 100.0 and not cmd.held
            assert cmd.verifier_status is VerifierStatus.OK
            assert cmd.radar_last_frame_mono_ns == 1_000 + cmd.radar_seq
            box, road = tgt.targets
            assert box.verification is Verification.VERIFIED
            assert road.verification is Verification.REJECTED
            assert road.decision is Decision.NONE and "camera rejected" in road.reason
            assert tgt.verifier == "edge_density" and tgt.verifier_params["tau"] == 0.025
            assert box.frame_age_ms is not None and abs(box.frame_age_ms) <= 500
            assert tgt.processing_ns > 0
            # The densities are the gate's, on the very frame fusion used.
            assert box.frame_seq is not None
            gray = decode_gray(frames.get(box.frame_seq).jpeg, 848, 480)
            for t in (box, road):
                r = Roi(*t.roi_xywh)
                patch = np.array(gray[r.y:r.y + r.h, r.x:r.x + r.w])
                assert t.density == np.count_nonzero(cv2.Canny(patch, 40, 120)) / patch.size
            assert box.density is not None and box.density > 0.04
            assert road.density is not None and road.density < 0.02

            # The threat vanishes: the brake is held (1.5 s), then the heartbeat is NONE.
            cmd, _ = radar.cycle()
            assert cmd.decision is Decision.BRAKE and cmd.held and cmd.track_id == 1
            wait_for(lambda: radar.cycle()[0].decision is Decision.NONE, 30, interval_s=0.05,
                     what="hold released")

            # A corrupt JPEG in the stream is counted; the neighbouring frames still serve.
            broken = bus.publisher(CAMERA_JPEG, camera="front")
            broken.put(broken_frame(10_000))
            wait_for(lambda: radar.cycle()[1].frames_undecodable >= 1, 30, interval_s=0.05,
                     what="corrupt frame counted")
            cmd, tgt = radar.cycle(track(1, *BOX, vx=-5.0))
            assert tgt.frames_undecodable == 1
            assert cmd.verifier_status is VerifierStatus.OK and cmd.decision is Decision.BRAKE

            # Stale radar never brakes, whatever the camera says.
            wait_for(lambda: radar.cycle()[0].decision is Decision.NONE, 30, interval_s=0.05,
                     what="hold released")
            cmd, tgt = radar.cycle(track(1, *BOX, vx=-5.0), age_ns=5_000_000_000)
            assert cmd.verifier_status is VerifierStatus.STALE_RADAR
            assert cmd.decision is Decision.NONE
            assert tgt.targets[0].verification is Verification.NOT_CHECKED

            # The camera stops; the only frame left near the cycle is corrupt: the verifier
            # is unavailable (not "no obstacle") and the threat becomes a WARNING.
            camera.signal(signal.SIGTERM)
            wait_for(lambda: not watch.is_alive("camera", "front"), 30, what="camera gone")
            broken.put(broken_frame(10_001))
            wait_for(lambda: (r := radar.cycle())[1].unavailable_reason.startswith(
                "newest frame unusable") and r[0].decision is Decision.NONE, 30,
                interval_s=0.05, what="verifier unavailable, no brake held")
            cmd, tgt = radar.cycle(track(1, *BOX, vx=-5.0))
            assert cmd.verifier_status is VerifierStatus.UNAVAILABLE
            assert "undecodable JPEG" in tgt.unavailable_reason
            assert tgt.targets[0].verification is Verification.UNAVAILABLE
            assert cmd.decision is Decision.WARNING and cmd.brake_level_pct == 0.0

            # Exactly one command per radar cycle, numbered one by one.
            cmds = commands.messages
            assert sorted(c.radar_seq for c in cmds) == list(range(radar.seq))
            seqs = [c.header.seq for c in cmds]
            assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))

            fusion.signal(signal.SIGTERM)
            wait_for(lambda: not fusion.alive(), 30, what="fusion exit")
            assert fusion.proc.returncode == 0, fusion.output()
            assert "fusion_stats" in fusion.output()
            # The camera published the calibration fusion uses: no mismatch warning.
            assert "camera_calibration_differs" not in fusion.output()
        finally:
            fusion.stop()
            camera.stop()


class Cameras:
    """Plays several cameras: each publishes its rendered frame every 40 ms with a fresh
    capture stamp, until switched off."""

    def __init__(self, bus, images: dict[str, np.ndarray]) -> None:
        self.pubs = {n: bus.publisher(CAMERA_JPEG, camera=n) for n in images}
        self.jpegs = {n: encode_jpeg(img, 80) for n, img in images.items()}
        self.on = set(images)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        seq = 0
        while not self.stop.wait(0.04):
            for name in list(self.on):
                self.pubs[name].put(CompressedFrame(
                    header=Header(seq=seq, source=f"camera/{name}", stamp_ns=wall_ns(),
                                  pub_mono_ns=0),
                    camera=name, width=848, height=480, jpeg=self.jpegs[name]))
            seq += 1


def test_fusion_process_with_two_cameras_verifies_each_track_where_it_is_seen(router, tmp_path):
    from tests.fusion.test_cameras import rig_cal

    names = ("front", "left")
    for n in names:
        (tmp_path / f"{n}.toml").write_text(rig_calibration_toml(n))
    cfg = tmp_path / "fusion.toml"
    cfg.write_text(f"""
[zenoh]
connect = ["{router}"]
[fusion]
instance = "{INSTANCE}"
stats_interval_s = 1.0
gate_scope = "all"                 # both threats gated, to see each camera's verdict
[[fusion.cameras]]
name = "front"
calibration = "{tmp_path / 'front.toml'}"
[[fusion.cameras]]
name = "left"
calibration = "{tmp_path / 'left.toml'}"
[fusion.frames]
max_skew_s = 0.5
frozen_after_s = 0.0    # still pictures, as above
[fusion.decision]
hold_s = 0.0
radar_max_age_s = 1.0
[fusion.decision.corridor]
enabled = false
""")
    ahead, left = (8.0, 0.8), (6.0, 6.0)      # a box in each camera's view only
    scene = Scene(obstacles=(Obstacle(*ahead), Obstacle(*left)), seed=4)
    with open_bus(router) as bus:
        watch = HealthWatch(bus)
        commands, targets = Collector(), Collector()
        bus.subscribe(FUSION_BRAKE_CMD, commands, instance=INSTANCE)
        bus.subscribe(FUSION_TARGETS, targets, instance=INSTANCE)
        cameras = Cameras(bus, {n: render(rig_cal(n), scene) for n in names})
        fusion = ServiceProcess("fusion", python_module("aeb_radar_camera.services.fusion", "-c",
                                                        str(cfg)),
                                tmp_path)
        try:
            watch.wait_alive("fusion", INSTANCE)
            cameras.thread.start()
            radar = Radar(bus, commands, targets)
            wait_for(lambda: not radar.cycle()[1].cameras_unavailable, 60, interval_s=0.05,
                     what="frames from both cameras")
            cmd, tgt = radar.cycle(track(1, *ahead, vx=-5.0), track(2, *left, vx=-5.0))
            one, two = tgt.targets
            assert (one.camera, one.verification) == ("front", Verification.VERIFIED)
            assert (two.camera, two.verification) == ("left", Verification.VERIFIED)
            assert [c.verification for c in two.cameras] == [Verification.NOT_VISIBLE,
                                                             Verification.VERIFIED]
            assert two.density is not None and two.density > 0.025
            assert cmd.decision is Decision.BRAKE and tgt.camera == "front,left"

            # The left camera stops: its track is unavailable (a warning), the other is not.
            cameras.on.discard("left")
            wait_for(lambda: "left" in radar.cycle()[1].cameras_unavailable, 30,
                     interval_s=0.05, what="left camera unavailable")
            cmd, tgt = radar.cycle(track(2, *left, vx=-5.0))
            assert tgt.verifier_status is VerifierStatus.OK
            assert tgt.targets[0].verification is Verification.UNAVAILABLE
            assert cmd.decision is Decision.WARNING
            cmd, tgt = radar.cycle(track(1, *ahead, vx=-5.0))
            assert cmd.decision is Decision.BRAKE and tgt.targets[0].camera == "front"

            fusion.signal(signal.SIGTERM)
            wait_for(lambda: not fusion.alive(), 30, what="fusion exit")
            assert fusion.proc.returncode == 0, fusion.output()
            assert "frames_left=" in fusion.output()
        finally:
            cameras.stop.set()
            fusion.stop()
