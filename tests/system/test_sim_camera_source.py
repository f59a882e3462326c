"""The simulator's camera plugin, without processes: extrapolation of sim/world to the
capture time, the empty road before the simulator starts, and a silent simulator as a
camera failure."""

from pathlib import Path

import numpy as np
import pytest

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.messages import Header
from aeb_radar_camera.services.camera.plugin import PluginContext, make_plugin_source
from aeb_radar_camera.services.camera.source import FrameSource, SourceConfigError, SourceError
from aeb_radar_camera.tools.messages import ObjectKind, SimObject, SimWorld
from aeb_radar_camera.tools.sim.camera_source import SimCameraSource, bodies_at

CALIBRATION = Path(__file__).resolve().parents[2] / "deploy/calibration/d435_848x480.toml"
S = 1_000_000_000


def world(stamp_ns: int, speed: float = 10.0, accel: float = 0.0, run: int = 1) -> SimWorld:
    ped = SimObject(0, ObjectKind.PEDESTRIAN, 20.0, -2.0, 90.0, 0.35, 0.55, 1.75, 0.0, 1.5)
    return SimWorld(header=Header(1, "sim", stamp_ns, 0), scenario="t", run=run, active=True,
                    t_s=1.0, ego_x_m=5.0, ego_speed_mps=speed, ego_accel_mps2=accel,
                    gap_m=None, ttc_s=None, objects=(ped,), seed=3, brightness=1.0, noise=0.0)


def test_world_is_extrapolated_to_the_capture_time():
    bodies, ego_x = bodies_at(world(10 * S), 10 * S + S // 10)        # 0.1 s later
    assert ego_x == pytest.approx(6.0)
    assert bodies[0].y_m == pytest.approx(-1.85) and bodies[0].x_m == 20.0
    _, ego_x = bodies_at(world(10 * S, speed=2.0, accel=-6.0), 10 * S + S // 5)
    assert ego_x == pytest.approx(5.0 + 2.0 * 0.2 - 3.0 * 0.2 ** 2)   # braking
    _, ego_x = bodies_at(world(10 * S, speed=1.0, accel=-6.0), 10 * S + S // 5)
    assert ego_x == pytest.approx(5.0 + 1.0 ** 2 / 12.0)              # stops, never reverses
    _, ego_x = bodies_at(world(10 * S), 10 * S + 5 * S)                 # capped at 0.25 s
    assert ego_x == pytest.approx(7.5)
    _, ego_x = bodies_at(world(10 * S), 9 * S)                          # never backwards
    assert ego_x == 5.0


def test_empty_road_first_then_the_world_then_a_silent_simulator_fails():
    clock = [100.0]
    cal = Calibration.load(CALIBRATION)
    source = SimCameraSource(cal, 30.0, None, stale_after_s=1.0, clock=lambda: clock[0],
                             sleep=lambda s: None, wall_clock=lambda: 10 * S)
    empty = source.read().image
    assert empty.shape == (480, 848, 3)
    source.on_world(world(10 * S))
    with_ped = source.read().image
    assert np.abs(with_ped.astype(int) - empty).sum() > 1000     # the pedestrian shows
    clock[0] += 2.0
    with pytest.raises(SourceError, match="no simulator world"):
        source.read()


def test_factory_needs_the_camera_bus_and_knows_its_options():
    cal = Calibration.load(CALIBRATION)
    ctx = PluginContext(848, 480, 30.0, cal)
    with pytest.raises(SourceConfigError, match="bus"):
        make_plugin_source("aeb_radar_camera.tools.sim.camera_source:make_source", ctx)
    ctx = PluginContext(848, 480, 30.0, cal, options={"colour": 1})
    with pytest.raises(SourceConfigError, match="colour"):
        make_plugin_source("aeb_radar_camera.tools.sim.camera_source:make_source", ctx)
    assert issubclass(SimCameraSource, FrameSource)


def test_frames_carry_aligned_depth_in_millimetres_unless_turned_off():
    cal = Calibration.load(CALIBRATION)
    source = SimCameraSource(cal, 30.0, None, clock=lambda: 100.0, sleep=lambda s: None,
                             wall_clock=lambda: 10 * S)
    source.on_world(world(10 * S, speed=0.0))
    frame = source.read()
    assert frame.depth is not None and frame.depth.dtype == np.uint16
    assert frame.depth.shape == frame.image.shape[:2]
    # the pedestrian's torso, 15 m ahead of the radar (20 m world, ego at 5 m), 0.8 m
    # behind it the camera: 15.8 m at the pixel where the colour shows them
    uv, _ = cal.project(np.array([[15.0, -2.0, 1.2]]))
    u, v = (int(np.rint(c)) for c in uv[0])
    assert abs(int(frame.depth[v, u]) - 15_800) <= 30
    assert frame.depth[5, 424] == 0                                   # the sky
    assert "exact depth" in source.describe()
    colour_only = SimCameraSource(cal, 30.0, None, clock=lambda: 100.0,
                                  sleep=lambda s: None, wall_clock=lambda: 10 * S, depth=False)
    assert colour_only.read().depth is None
    noisy = SimCameraSource(cal, 30.0, None, clock=lambda: 100.0, sleep=lambda s: None,
                            wall_clock=lambda: 10 * S, depth_noise=True)
    noisy.on_world(world(10 * S, speed=0.0))
    d = noisy.read().depth
    assert d is not None and 15_000 < int(np.median(d[v - 3:v + 4, u - 2:u + 3])) < 16_600
    assert not np.array_equal(d, frame.depth)
