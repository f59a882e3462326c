"""The RealSense source against the real pyrealsense2, on a recording made here by a
librealsense software device (no camera needed). Needs the optional extra `realsense`;
without it this module is skipped and the wrapper is still covered by the stand-in
tests in test_sources.py."""

import time
from pathlib import Path

import numpy as np
import pytest

rs = pytest.importorskip(
    "pyrealsense2",
    reason="optional extra not installed (pip install 'aeb-radar-camera[realsense]'); "
           "test_sources.py covers the wrapper with a stand-in")

from aeb_radar_camera.services.camera.realsense import RealSenseSource  # noqa: E402
from aeb_radar_camera.services.camera.source import EndOfStream, Frame  # noqa: E402

W, H, FPS, N = 848, 480, 30, 8


def record(path: Path) -> None:
    """N colour frames (grey level 10 * i) through a software device into a recording."""
    dev = rs.software_device()
    sensor = dev.add_sensor("RGB Camera")
    intr = rs.intrinsics()
    intr.width, intr.height, intr.fx, intr.fy, intr.ppx, intr.ppy = W, H, 615.0, 615.0, 424.0, 240.0
    intr.model, intr.coeffs = rs.distortion.brown_conrady, [0.0] * 5
    vs = rs.video_stream()
    vs.type, vs.index, vs.uid = rs.stream.color, 0, 0
    vs.width, vs.height, vs.fps, vs.bpp, vs.fmt, vs.intrinsics = W, H, FPS, 3, rs.format.bgr8, intr
    profile = sensor.add_video_stream(vs)
    recorder = rs.recorder(str(path), dev)
    sensor.open(profile)
    sensor.start(lambda frame: None)
    for i in range(N):
        f = rs.software_video_frame()
        f.pixels = np.full((H, W, 3), 10 * i, np.uint8)
        f.bpp, f.stride = 3, W * 3
        f.timestamp, f.domain = i * 1000.0 / FPS, rs.timestamp_domain.hardware_clock
        f.frame_number, f.profile = i, profile.as_video_stream_profile()
        sensor.on_video_frame(f)
        time.sleep(1 / FPS)   # the recorder stores arrival times: record at the real rate
    sensor.stop()
    sensor.close()
    del recorder   # closes the file


def recording_path(tmp_path: Path) -> Path:
    # librealsense 2.59 records ROS 2 bags (.db3); older versions write .bag.
    for suffix in (".db3", ".bag"):
        path = tmp_path / f"drive{suffix}"
        try:
            record(path)
            return path
        except RuntimeError as exc:
            if "extension" not in str(exc):
                raise
    raise AssertionError("librealsense accepted neither .db3 nor .bag")


def test_realsense_source_plays_a_recording_in_order_and_ends(tmp_path):
    path = recording_path(tmp_path)
    src = RealSenseSource(bag=str(path), timeout_ms=500)
    src.open()
    frames: list[Frame] = []
    try:
        with pytest.raises(EndOfStream, match="end of recording"):
            while len(frames) <= N:
                frames.append(src.read())
    finally:
        src.close()
    assert [int(f.image.mean()) for f in frames] == [10 * i for i in range(N)]
    assert all(f.image.shape == (H, W, 3) and f.image.dtype == np.uint8 for f in frames)
    stamps = [f.stamp_ns for f in frames]
    assert stamps == sorted(stamps) and abs(stamps[-1] - time.time_ns()) < 10e9
