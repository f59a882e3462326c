"""The simulator's depth on the bus: the real camera service, fed by the simulator's
camera plugin, publishes a DepthFrame beside each JPEG with the same capture stamp, and
its pixels are the scene's geometry."""

import os
import threading

import numpy as np
import pytest

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.depth_image import decode_depth, to_metres
from aeb_radar_camera.common.keys import CAMERA_DEPTH, CAMERA_JPEG
from aeb_radar_camera.common.messages import CompressedFrame, DepthFrame
from aeb_radar_camera.common.resources import EXAMPLE_CALIBRATION
from aeb_radar_camera.tools.sim.scenario import find_scenario, load_scenario
from aeb_radar_camera.tools.sim.session import closed_loop

pytestmark = pytest.mark.slow


def test_the_camera_publishes_the_simulated_depth_with_each_frame(tmp_path):
    jpeg_stamps: set[int] = set()
    depths: list[DepthFrame] = []
    enough = threading.Event()
    lock = threading.Lock()

    def on_jpeg(msg: CompressedFrame, key: str) -> None:
        with lock:
            jpeg_stamps.add(msg.header.stamp_ns)

    def on_depth(msg: DepthFrame, key: str) -> None:
        with lock:
            depths.append(msg)
            if len(depths) >= 20:
                enough.set()

    with closed_loop(tmp_path) as loop:
        loop.bus.subscribe(CAMERA_JPEG, on_jpeg, camera="front")
        loop.bus.subscribe(CAMERA_DEPTH, on_depth, camera="front")
        sc = load_scenario(find_scenario("no_threat_manhole_30kph"))
        loop.sim.run(sc, timeout_s=3.0)
        assert enough.wait(60.0), f"{len(depths)} depth frames"
        assert (tmp_path / "run" / "actuator").is_symlink()
    # the session removed the actuator's pty link with the pty: nothing dangles in run/
    assert not os.path.lexists(tmp_path / "run" / "actuator")
    with lock:
        paired = [d for d in depths if d.header.stamp_ns in jpeg_stamps]
        assert len(paired) >= 0.8 * len(depths)        # the JPEGs' own stamps
        last = depths[-1]
    assert (last.width, last.height) == (424, 240)        # decimated by 2
    depth = to_metres(decode_depth(last.data, last.codec, last.width, last.height))
    cal = Calibration.load(EXAMPLE_CALIBRATION)
    # A ground pixel's depth is where its ray meets the road, wherever the ego is (the
    # cover is farther ahead than this pixel); the sky has none.
    uv, _ = cal.project(np.array([[10.0, 0.0, 0.0]]))
    u, v = (int(np.rint(c / 2)) for c in uv[0])
    assert depth[v, u] == pytest.approx(10.8, abs=0.15)
    assert depth[2, 212] == 0.0
