"""The simulated camera on a bend and in other light: lane markings, roadside and depth
follow the curve, the vehicle frame is what it draws, night is lit only within the low
beams, dusk is darker, rain washes the contrast out."""

import math

import numpy as np
import pytest

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.resources import EXAMPLE_CALIBRATION
from aeb_radar_camera.tools.messages import Lighting, ObjectKind, RoadGeometry, SimWorld
from aeb_radar_camera.tools.sim.camera_source import scene_at
from aeb_radar_camera.tools.sim.render import ROADSIDE_Y_M, Renderer
from aeb_radar_camera.tools.sim.road import Road, RoadView
from aeb_radar_camera.tools.sim.scenario import (
    CameraLook,
    EgoSpec,
    RoadSpec,
    Scenario,
    ScenarioKind,
    SceneObject,
)
from aeb_radar_camera.tools.sim.sprites import LANE_WIDTH_M
from aeb_radar_camera.tools.sim.world import Body, World

QUIET = CameraLook(noise=0.0)
EDGE_LINE_M = 1.5 * LANE_WIDTH_M          # the solid line at the road's edges


@pytest.fixture(scope="module")
def cal() -> Calibration:
    return Calibration.load(EXAMPLE_CALIBRATION)


@pytest.fixture(scope="module")
def plain(cal) -> Renderer:
    return Renderer(cal, seed=3, look=QUIET, roadside=False)


@pytest.fixture(scope="module")
def roadside(cal) -> Renderer:
    return Renderer(cal, seed=3, look=QUIET)


def pixel(cal: Calibration, x: float, y: float, z: float) -> tuple[int, int]:
    uv, ok = cal.project(np.array([[x, y, z]]))
    assert ok[0]
    return round(float(uv[0, 0])), round(float(uv[0, 1]))


def camera_z(cal: Calibration, x: float, y: float, z: float) -> float:
    return float((cal.r @ np.array([x, y, z]) + cal.t)[2])


def in_vehicle_frame(view: RoadView, s: float, d: float) -> tuple[float, float]:
    xy = view.road.to_world(np.array([s]), np.array([d]))
    p = view.pose.to_local(xy)[0]
    return float(p[0]), float(p[1])


@pytest.mark.parametrize("radius", [50.0, -50.0, 120.0])
def test_lane_markings_and_depth_follow_the_bend(plain, cal, radius):
    """The solid edge line 6-15 m further along the bend is drawn where its road
    coordinates project (brighter than the asphalt half a metre inside it), with the
    depth of that ground point; on the straight road those pixels are off the line."""
    view = RoadView(Road(RoadGeometry(curve_start_m=0.0, radius_m=radius)), 30.0)
    img, depth = plain.render_rgbd([], 0.0, road=view)
    gray = img.mean(axis=2)
    straight = plain.render([], 30.0).mean(axis=2)

    def at(ahead: float, d: float) -> tuple[int, int, float, float]:
        x, y = in_vehicle_frame(view, 30.0 + ahead, d)
        u, v = pixel(cal, x, y, 0.0)
        return u, v, float(gray[v - 1:v + 2, u - 1:u + 2].max()), camera_z(cal, x, y, 0.0)

    checked = 0
    for ahead in (6.0, 10.0, 15.0):      # farther, the coarse texture levels blur it
        for side in (1.0, -1.0):
            x, y = in_vehicle_frame(view, 30.0 + ahead, side * EDGE_LINE_M)
            u, v = pixel(cal, x, y, 0.0)
            if not (2 <= u < cal.width - 2 and 2 <= v < cal.height - 2):
                continue                  # out of the camera's view
            checked += 1
            u, v, line, z = at(ahead, side * EDGE_LINE_M)
            inside = at(ahead, side * (EDGE_LINE_M - 0.5))[2]
            assert line > inside + 8, (ahead, side)
            assert depth[v, u] == pytest.approx(z, rel=0.03)
            if ahead == 15.0 and abs(radius) < 100:
                assert straight[v - 1:v + 2, u - 1:u + 2].max() < line - 8
    assert checked >= 4


def test_markings_curve_left_and_right(plain, cal):
    """Where the road's far markings are: left of the straight road's on a left bend,
    right of them on a right bend."""
    def marking_column(radius: float | None) -> float:
        geometry = RoadGeometry(curve_start_m=0.0, radius_m=radius)
        gray = plain.render([], 30.0, road=RoadView(Road(geometry), 30.0)).mean(axis=2)
        _, v_far = pixel(cal, 14.0, 0.0, 0.0)
        band = gray[v_far:v_far + 10]
        return float(np.nonzero(band > np.median(band) + 30)[1].mean())

    straight, left, right = marking_column(None), marking_column(60.0), marking_column(-60.0)
    assert left < straight - 20 and right > straight + 20


def test_the_roadside_follows_the_bend_and_the_geometry_is_kept_on_the_arc(roadside, cal):
    road = Road(RoadGeometry(curve_start_m=10.0, radius_m=-60.0))
    view = RoadView(road, 40.0)
    _, depth = roadside.render_rgbd([], 0.0, road=view)
    for ahead, side in ((15.0, 1.0), (25.0, -1.0)):
        # The wall beside the road at this station, 3 m up, where nearer than the bend
        # hides it: its depth is there.
        x, y = in_vehicle_frame(view, 40.0 + ahead, side * (ROADSIDE_Y_M + 0.05))
        u, v = pixel(cal, x, y, 3.0)
        if 0 <= u < cal.width and 0 <= v < cal.height:
            assert depth[v, u] == pytest.approx(camera_z(cal, x, y, 3.0), rel=0.05)
    # On the arc every station sees the same road: the geometry is built once.
    assert roadside._geometry(RoadView(road, 40.0)) is roadside._geometry(RoadView(road, 47.3))
    approaching = roadside._geometry(RoadView(road, 2.0))
    assert approaching is not roadside._geometry(RoadView(road, 5.0))
    # Far enough before a bend the view is the straight one.
    far = Road(RoadGeometry(curve_start_m=400.0, radius_m=60.0))
    assert roadside._geometry(RoadView(far, 10.0)) is roadside._straight


def test_the_camera_source_draws_the_vehicle_frame_along_the_road():
    sc = Scenario(name="t", kind=ScenarioKind.THREAT, ego=EgoSpec(speed_kph=36.0),
                  object=(SceneObject(ObjectKind.CAR, 60.0, 0.0),
                          SceneObject(ObjectKind.BOX, 45.0, -3.0)),
                  road=RoadSpec(curve_start_m=5.0, radius_m=50.0))
    world = World(sc)
    world.step(2.5, 0.0)
    pose = world.ego_pose()
    from aeb_radar_camera.common.messages import Header

    msg = SimWorld(header=Header(0, "sim", 1_000_000_000, 0), scenario="t", run=1,
                   active=True, t_s=world.t_s, ego_x_m=pose.x_m,
                   ego_speed_mps=world.ego.speed_mps, ego_accel_mps2=0.0, gap_m=None,
                   ttc_s=None, objects=tuple(world.bodies()), seed=1, brightness=1.0,
                   noise=2.0, ego_y_m=pose.y_m, ego_heading_deg=math.degrees(pose.heading_rad),
                   ego_yaw_rate_dps=world.yaw_rate_dps(), ego_s_m=world.ego.s_m,
                   road=sc.road)
    view = scene_at(msg, 1_000_000_000)
    assert view.ego_x_m == pytest.approx(world.ego.s_m)
    for seen, truth in zip(view.bodies, world.vehicle_bodies(), strict=True):
        assert seen.x_m - view.ego_x_m == pytest.approx(truth.x_m)
        assert seen.y_m == pytest.approx(truth.y_m) and seen.yaw_deg == pytest.approx(
            truth.yaw_deg)
    # 0.1 s later: the ego has moved 1 m along the arc and turned with it.
    later = scene_at(msg, 1_100_000_000)
    world.step(0.1, 0.0)
    for seen, truth in zip(later.bodies, world.vehicle_bodies(), strict=True):
        assert (seen.x_m - later.ego_x_m, seen.y_m) == pytest.approx((truth.x_m, truth.y_m),
                                                                     abs=1e-6)


def _patch(gray: np.ndarray, uv: tuple[int, int], r: int = 3) -> float:
    u, v = uv
    return float(gray[v - r:v + r + 1, u - r:u + r + 1].mean())


def test_at_night_the_scene_is_lit_only_within_the_beams(cal):
    r = Renderer(cal, seed=3, look=QUIET, lighting=Lighting.NIGHT)
    gray = r.render([], 0.0).mean(axis=2)
    in_beam, outside = pixel(cal, 8.0, 0.0, 0.0), pixel(cal, 8.0, 6.0, 0.0)
    assert _patch(gray, in_beam) > 2.5 * _patch(gray, outside)
    day = Renderer(cal, seed=3, look=QUIET).render([], 0.0).mean(axis=2)
    assert _patch(gray, outside) < 0.2 * _patch(day, outside)       # ambient light only
    # The same pedestrian inside the beam and outside it (left of the cone).
    ped = [Body(0, ObjectKind.PEDESTRIAN, 10.0, 0.0, 180.0, 0.35, 0.55, 1.75, 0.0, 0.0),
           Body(1, ObjectKind.PEDESTRIAN, 10.0, 7.0, 180.0, 0.35, 0.55, 1.75, 0.0, 0.0)]
    lit = r.render(ped, 0.0).mean(axis=2)
    lit_ped, dark_ped = pixel(cal, 10.0, 0.0, 1.1), pixel(cal, 10.0, 7.0, 1.1)
    assert _patch(lit, lit_ped, 2) > 3 * _patch(lit, dark_ped, 2)


def test_dusk_is_darker_and_rain_washes_the_contrast_out(cal):
    car = [Body(0, ObjectKind.CAR, 15.0, 0.0, 0.0, 4.4, 1.8, 1.5, 0.0, 0.0)]
    r = Renderer(cal, seed=3, look=QUIET)
    day = r.render(car, 0.0).astype(float)
    r.set_look(QUIET, Lighting.DUSK)
    dusk = r.render(car, 0.0).astype(float)
    assert dusk.mean() < 0.5 * day.mean()
    r.set_look(QUIET, Lighting.RAIN)
    rain = [r.render(car, 0.0).astype(float) for _ in range(2)]
    assert rain[0].std() < 0.75 * day.std()
    assert not np.array_equal(rain[0], rain[1])            # the drops fall
    r.set_look(QUIET, Lighting.DAY)
    assert np.array_equal(r.render(car, 0.0).astype(float), day)
