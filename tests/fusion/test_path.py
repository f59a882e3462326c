"""The kinematic rule's predicted path (services/fusion/path.py)."""

import math

import pytest

from aeb_radar_camera.common.config.fusion import PathSettings
from aeb_radar_camera.services.fusion.path import PredictedPath, curvature, predicted_path


def on_arc(radius_m: float, s_m: float, d_m: float = 0.0) -> tuple[float, float]:
    """The point at arc length s and offset d (left positive) of an arc from the origin
    along x, radius > 0 left, < 0 right."""
    phi = s_m / abs(radius_m)
    sign = 1.0 if radius_m > 0 else -1.0
    rho = abs(radius_m) - sign * d_m
    return rho * math.sin(phi), sign * (abs(radius_m) - rho * math.cos(phi))


@pytest.mark.parametrize("radius", [50.0, -50.0, 250.0, -100.0])
@pytest.mark.parametrize("s,d", [(0.0, 0.0), (10.0, 0.0), (30.0, 1.0), (30.0, -1.5),
                                 (60.0, 0.4)])
def test_points_on_an_arc_get_their_arc_length_and_offset(radius: float, s: float,
                                                          d: float) -> None:
    path = PredictedPath(1.0 / radius, 1.2, 80.0)
    x, y = on_arc(radius, s, d)
    p = path.point(x, y)
    assert p.s_m == pytest.approx(s, abs=1e-6)
    assert p.d_m == pytest.approx(d, abs=1e-6)


def test_the_outside_of_a_bend_is_not_in_the_path_though_straight_ahead_it_would_be() -> None:
    # A post 1.5 m outside a 50 m left bend, 25 m along it: straight ahead of the radar
    # by its lateral offset? No: the bend has turned away from it by then.
    x, y = on_arc(50.0, 25.0, -1.5)
    bend = PredictedPath(1 / 50.0, 1.2, 80.0)
    assert not bend.contains(bend.point(x, y))
    # A car stopped in the lane 25 m into the bend: out of a straight corridor, in the path.
    cx, cy = on_arc(50.0, 25.0, 0.0)
    straight = PredictedPath(0.0, 1.2, 80.0)
    assert abs(cy) > 1.2 and not straight.contains(straight.point(cx, cy))
    assert bend.contains(bend.point(cx, cy))


def test_length_and_behind_the_radar_bound_the_path() -> None:
    path = PredictedPath(0.0, 1.2, 40.0)
    assert path.contains(path.point(39.0, 0.0))
    assert not path.contains(path.point(41.0, 0.0))
    assert not path.contains(path.point(-1.0, 0.0))


def test_centre_line_offset_shifts_the_path() -> None:
    path = PredictedPath(0.0, 1.2, 80.0, center_y_m=0.5)
    assert path.point(10.0, 1.6).d_m == pytest.approx(1.1)
    assert path.contains(path.point(10.0, 1.6))
    assert not path.contains(path.point(10.0, -0.8))


def test_velocity_in_path_axes_follows_the_tangent() -> None:
    path = PredictedPath(1 / 50.0, 1.2, 80.0)
    s = 50.0 * math.pi / 2        # a quarter turn: the tangent points along +y
    x, y = on_arc(50.0, s)
    along, across = path.velocity(path.point(x, y), 0.0, 3.0)
    assert along == pytest.approx(3.0)
    assert across == pytest.approx(0.0, abs=1e-9)


def test_curvature_from_yaw_rate_above_the_minimum_speed() -> None:
    s = PathSettings(min_yaw_speed_mps=3.0)
    k, source = curvature(10.0, math.degrees(0.2), None, s)
    assert (k, source) == (pytest.approx(0.02), "yaw rate")


def test_low_speed_uses_the_steering_wheel_only_with_a_wheelbase() -> None:
    noisy_yaw = 5.0     # deg/s at 1 m/s would be a 11 m radius
    without = PathSettings(min_yaw_speed_mps=3.0)
    assert curvature(1.0, noisy_yaw, 30.0, without) == (0.0, "straight")
    with_wb = PathSettings(min_yaw_speed_mps=3.0, wheelbase_m=2.7, steering_ratio=15.0)
    k, source = curvature(1.0, noisy_yaw, 30.0, with_wb)
    assert source == "steering"
    assert k == pytest.approx(math.tan(math.radians(2.0)) / 2.7)
    # No steering signal from this car: straight, said so.
    assert curvature(1.0, noisy_yaw, None, with_wb) == (0.0, "straight")


def test_curvature_is_clipped() -> None:
    s = PathSettings(max_curvature_per_m=0.05)
    assert curvature(5.0, math.degrees(2.0), None, s)[0] == pytest.approx(0.05)
    assert curvature(5.0, -math.degrees(2.0), None, s)[0] == pytest.approx(-0.05)


def test_predicted_path_width_is_half_width_plus_margin() -> None:
    path = predicted_path(10.0, 0.0, None, PathSettings(half_width_m=0.9, margin_m=0.3,
                                                        length_m=60.0))
    assert (path.half_width_m, path.length_m, path.curvature_per_m) == (
        pytest.approx(1.2), 60.0, 0.0)
    assert "straight" in path.describe()
    assert "R 50 m left" in PredictedPath(0.02, 1.2, 80.0, source="yaw rate").describe()


@pytest.mark.parametrize("radius", [50.0, -50.0, 1e9])
def test_at_places_arc_length_and_offset_back_in_the_vehicle_frame(radius: float) -> None:
    path = PredictedPath(1.0 / radius, 1.2, 80.0, center_y_m=0.3)
    for s, d in ((0.0, 0.0), (10.0, 1.2), (35.0, -0.9)):
        x, y = path.at(s, d)
        ex, ey = on_arc(radius, s, d)
        assert (x, y) == pytest.approx((ex, ey + 0.3), abs=1e-6)
        back = path.point(x, y)
        assert (back.s_m, back.d_m) == pytest.approx((s, d), abs=1e-6)
