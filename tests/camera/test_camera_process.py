"""The camera as its own process on an image folder, through a Zenoh router."""

import itertools
import signal

import numpy as np
import pytest

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.imaging import decode_gray
from aeb_radar_camera.common.keys import CAMERA_INFO, CAMERA_JPEG
from tests.camera.helpers import CALIBRATION, folder_config, write_folder
from tests.support import Collector, HealthWatch, ServiceProcess, open_bus, python_module, wait_for

pytestmark = pytest.mark.slow


def test_camera_process_publishes_frames_and_answers_info_queries(router, tmp_path):
    write_folder(tmp_path / "frames", 4, corrupt=("frame2b.jpg", "notes.png"))
    cfg = folder_config(tmp_path / "camera.toml", router, tmp_path / "frames", fps=20.0)
    with open_bus(router) as bus:
        watch = HealthWatch(bus)
        frames = Collector()
        bus.subscribe(CAMERA_JPEG, frames, camera="front")
        infos = Collector()
        bus.subscribe(CAMERA_INFO, infos, camera="front")
        cam = ServiceProcess("camera", python_module("aeb_radar_camera.services.camera", "-c",
                                                     str(cfg)),
                             tmp_path)
        try:
            watch.wait_alive("camera", "front")
            got = frames.wait_count(10, 60)[:10]

            seqs = [m.header.seq for m in got]
            assert seqs == list(range(seqs[0], seqs[0] + 10))
            stamps = [m.header.stamp_ns for m in got]
            assert all(b > a for a, b in itertools.pairwise(stamps))
            assert {(m.camera, m.width, m.height) for m in got} == {("front", 848, 480)}
            for m in got:
                assert decode_gray(m.jpeg, 848, 480).shape == (480, 848)
            assert frames.items[0][1] == "aeb/ego/camera/front/jpeg"

            # 10 frames from a folder of 4 good files: it looped, skipping both bad files
            # on every pass; the query answers with the calibration and the counters.
            replies = wait_for(lambda: bus.query(CAMERA_INFO, 5.0, camera="front"), 30,
                               what="CameraInfo reply")
            info, key = replies[0]
            assert key == "aeb/ego/camera/front/info"
            cal = Calibration.load(CALIBRATION)
            assert (info.width, info.height, info.source) == (848, 480, "folder")
            np.testing.assert_allclose(np.reshape(info.k, (3, 3)), cal.k)
            np.testing.assert_allclose(np.reshape(info.r, (3, 3)), cal.r, atol=1e-12)
            np.testing.assert_allclose(info.t_m, cal.t, atol=1e-12)
            assert info.errors["unreadable_input"] >= 4
            assert info.read_errors >= 4
            assert info.frames_published >= 10
            assert info.healthy and info.status == ""

            # The periodic CameraInfo arrives too.
            periodic = infos.wait_count(1, 30)[0]
            assert periodic.camera == "front" and periodic.k == info.k

            cam.signal(signal.SIGTERM)
            wait_for(lambda: not cam.alive(), 30, what="camera exit")
            assert cam.proc.returncode == 0, cam.output()
            wait_for(lambda: not watch.is_alive("camera", "front"), 30, what="token gone")
        finally:
            cam.stop()


def test_a_stalling_camera_is_reported_unhealthy_and_reopened(router, tmp_path):
    cfg = tmp_path / "camera.toml"
    cfg.write_text(f"""
[zenoh]
connect = ["{router}"]
[camera]
name = "sim"
calibration = "{CALIBRATION}"
fps = 30.0
stall_timeout_s = 0.3
info_period_s = 0.1
reopen_initial_s = 0.2
stats_period_s = 0
[camera.source]
kind = "synthetic"
factory = "tests.camera.plugins:stalling"
options = {{ frames_per_open = 5, stall_s = 1.0 }}
""")
    with open_bus(router) as bus:
        watch = HealthWatch(bus)
        infos = Collector()
        bus.subscribe(CAMERA_INFO, infos, camera="sim")
        frames = Collector()
        bus.subscribe(CAMERA_JPEG, frames, camera="sim")
        cam = ServiceProcess("camera-sim", python_module("aeb_radar_camera.services.camera", "-c",
                                                         str(cfg)),
                             tmp_path)
        try:
            watch.wait_alive("camera", "sim")
            stalled = infos.wait_until(lambda m: not m.healthy and "no frame" in m.status, 60)
            assert stalled.source == "synthetic"
            failed = infos.wait_until(lambda m: "reopening in" in m.status, 60)
            assert "no frame within 1.0 s" in failed.status
            back = infos.wait_until(lambda m: m.healthy and m.reopens >= 1, 60)
            assert back.errors["source_error"] >= 1
            # Frames flowed before and after the reopen, numbered without gaps.
            frames.wait_count(6, 60)
            seqs = [m.header.seq for m in frames.messages]
            assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
        finally:
            cam.stop()
        assert cam.proc.returncode == 0, cam.output()
