"""The fusion process and a camera that repeats one picture of the empty road with fresh
sensor noise (sigma 2 grey levels, a valid CRC-32 on every frame): while a car stands
still ahead of a standing ego the camera is used as any live one; once the radar sees
the car close at 30 km/h, the camera is reported frozen, the threat gets the
unverifiable policy's WARNING (not the verifier's "nothing there" on an old picture),
the shell counts `camera_frozen` and logs it."""

import signal
import threading

import numpy as np

from aeb_radar_camera.common.clock import wall_ns
from aeb_radar_camera.common.imaging import encode_jpeg, jpeg_crc32
from aeb_radar_camera.common.keys import CAMERA_JPEG, FUSION_BRAKE_CMD, FUSION_TARGETS
from aeb_radar_camera.common.messages import (
    BrakeCommand,
    CompressedFrame,
    Decision,
    Header,
    VerifiedTargets,
    VerifierStatus,
)
from aeb_radar_camera.services.fusion.frames import FROZEN_REASON
from aeb_radar_camera.tools.sim.scenes import Scene, render
from tests.fusion.helpers import CAL, CALIBRATION, track
from tests.fusion.test_fusion_processes import INSTANCE, Radar
from tests.support import Collector, HealthWatch, ServiceProcess, open_bus, python_module, wait_for

SIGMA = 2.0


class NoisyStillCamera:
    """Publishes one picture every 33 ms, each time with fresh Gaussian noise, a fresh
    capture stamp and its own CRC-32, until stopped."""

    def __init__(self, bus, picture: np.ndarray) -> None:
        self.pub = bus.publisher(CAMERA_JPEG, camera="front")
        self.picture = picture.astype(np.float64)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.rng = np.random.default_rng(28)

    def _run(self) -> None:
        seq = 0
        while not self.stop.wait(0.033):
            noisy = self.picture + self.rng.normal(0.0, SIGMA, self.picture.shape)
            jpeg = encode_jpeg(np.clip(noisy, 0, 255).astype(np.uint8), 80)
            self.pub.put(CompressedFrame(
                header=Header(seq=seq, source="camera/front", stamp_ns=wall_ns(),
                              pub_mono_ns=0),
                camera="front", width=CAL.width, height=CAL.height, jpeg=jpeg,
                crc32=jpeg_crc32(jpeg)))
            seq += 1


def test_a_noisy_repeated_picture_is_a_frozen_camera_once_a_car_closes(router, tmp_path):
    cfg = tmp_path / "fusion.toml"
    cfg.write_text(f"""
[zenoh]
connect = ["{router}"]
[fusion]
instance = "{INSTANCE}"
calibration = "{CALIBRATION}"
stats_interval_s = 1.0
[fusion.frames]
max_skew_s = 0.5          # a loaded machine may delay a frame; this test is not about skew
frozen_after_s = 0.5
[fusion.decision]
hold_s = 0.0
radar_max_age_s = 1.0
""")
    empty_road = render(CAL, Scene(seed=4))
    with open_bus(router) as bus:
        watch = HealthWatch(bus)
        commands, targets = Collector(), Collector()
        bus.subscribe(FUSION_BRAKE_CMD, commands, instance=INSTANCE)
        bus.subscribe(FUSION_TARGETS, targets, instance=INSTANCE)
        camera = NoisyStillCamera(bus, empty_road)
        fusion = ServiceProcess("fusion", python_module("aeb_radar_camera.services.fusion", "-c",
                                                        str(cfg)),
                                tmp_path)
        try:
            watch.wait_alive("fusion", INSTANCE)
            camera.thread.start()
            radar = Radar(bus, commands, targets)
            parked = track(x=10.0, vx=0.0)
            wait_for(lambda: radar.cycle(parked)[1].verifier_status is VerifierStatus.OK,
                     60, interval_s=0.05, what="camera frames used")
            # Standing ego, still scene: one picture up to noise for more than
            # frozen_after_s, and the camera is used all along
            start = wall_ns()
            while wall_ns() - start < 1_500_000_000:
                cmd, tgt = radar.cycle(parked)
                assert tgt.verifier_status is VerifierStatus.OK, tgt.unavailable_reason
                assert tgt.cameras_unavailable == {}
            # The car closes at 30 km/h, 10 m ahead: a live picture would show it grow
            closing = track(x=10.0, vx=-8.3)
            seen: list[tuple[BrakeCommand, VerifiedTargets]] = []

            def frozen_reported() -> bool:
                seen.append(radar.cycle(closing))
                return seen[-1][1].unavailable_reason == FROZEN_REASON

            wait_for(frozen_reported, 30, interval_s=0.0, what="camera reported frozen")
            cmd, tgt = seen[-1]
            assert tgt.verifier_status is VerifierStatus.UNAVAILABLE
            assert cmd.decision is Decision.WARNING, cmd.reason
            assert FROZEN_REASON in cmd.reason
            fusion.signal(signal.SIGTERM)
            wait_for(lambda: not fusion.alive(), 30, what="fusion exit")
            assert fusion.proc.returncode == 0, fusion.output()
            out = fusion.output()
            assert "camera_frozen camera=front" in out and "camera_frozen=" in out, out[-3000:]
        finally:
            camera.stop.set()
            if camera.thread.is_alive():
                camera.thread.join(10)     # before the bus closes under its publisher
            fusion.stop()
