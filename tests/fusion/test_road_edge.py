"""The road's edge from stationary radar returns (services/fusion/road_edge.py): a guard
rail along a bend's outside is out of the straight path, a car stopped in the lane beside
or beyond a straight rail stays in it; and the kinematic rule and the core with it."""
import itertools
import math

import pytest

from aeb_radar_camera.common.config.fusion import RoadEdgeSettings
from aeb_radar_camera.common.messages import Decision, RadarTrack
from aeb_radar_camera.services.fusion.evidence import ROAD_EDGE
from aeb_radar_camera.services.fusion.road_edge import (
    EdgePoint,
    bounded_fit,
    curvature_limit,
    on_edge,
    quadratic_fit,
    road_edges,
)
from tests.fusion.helpers import track
from tests.fusion.test_decision_kinematic import Drive

S = RoadEdgeSettings()
HALF = 1.2                  # the path's half width with its margin (deploy/fusion.toml)
CAP = 0.05                  # the path's max_curvature_per_m
KPH = 1 / 3.6


def rail(radius_m: float | None, curve_start_m: float = 20.0, first_m: float = 8.0,
         last_m: float = 65.0, offset_m: float = 2.6, step_m: float = 4.0,
         ego_m: float = 0.0, id0: int = 100) -> list[EdgePoint]:
    """A rail's returns every `step_m` along the outside edge (right of a left bend, left
    of a right one; right on a straight road), as the ego at station `ego_m` on the
    straight sees them: (x, y) in the straight path's coordinates."""
    side = -1.0 if radius_m is None or radius_m > 0 else 1.0
    out = []
    n = int((last_m - first_m) / step_m) + 1
    for i in range(n):
        st = first_m + i * step_m
        if radius_m is None or st <= curve_start_m:
            x, y = st, side * offset_m
        else:
            r = radius_m - side * offset_m          # the rail's signed radius
            th = (st - curve_start_m) / radius_m
            x, y = curve_start_m + r * math.sin(th), radius_m - r * math.cos(th)
        if x - ego_m > 0.5:
            out.append(EdgePoint(id0 + i, x - ego_m, y))
    return out


def edge_ids(points: list[EdgePoint], speed_mps: float, curvature: float = 0.0,
             s: RoadEdgeSettings = S) -> dict[int, str]:
    return on_edge(road_edges(points, HALF, curvature, speed_mps, s, CAP), s)


def in_path(points: list[EdgePoint]) -> list[EdgePoint]:
    return [p for p in points if abs(p.d_m) <= HALF]


# -- the fits ----------------------------------------------------------------------------------


def test_quadratic_fit_recovers_a_parabola_far_ahead():
    pts = [(x, 0.3 - 0.02 * x + 0.01 * x * x) for x in (40.0, 44.0, 48.0, 52.0, 56.0)]
    c0, c1, c2 = quadratic_fit(pts)
    assert (c0, c1, c2) == pytest.approx((0.3, -0.02, 0.01), abs=1e-6)
    assert quadratic_fit([(0.0, 1.0), (2.0, 2.0)]) == pytest.approx((1.0, 0.5, 0.0))
    with pytest.raises(ValueError):
        quadratic_fit([])


def test_bounded_fit_holds_the_curvature_within_its_bounds():
    pts = [(x, 0.05 * x * x) for x in (0.0, 4.0, 8.0, 12.0)]
    assert bounded_fit(pts, -1.0, 1.0)[2] == pytest.approx(0.05)
    c0, c1, c2 = bounded_fit(pts, -0.01, 0.01)
    assert c2 == 0.01
    # The rest is the least squares line through what the bounded term leaves.
    assert max(abs(c0 + c1 * x + c2 * x * x - y) for x, y in pts) > 0.5


def test_the_curvature_bound_is_a_drivable_bend_at_the_ego_s_speed():
    assert curvature_limit(50 * KPH, S, CAP) == pytest.approx(5.0 / (50 * KPH) ** 2)
    assert curvature_limit(10 * KPH, S, CAP) == CAP          # the path's cap at a crawl
    assert curvature_limit(0.0, S, CAP) == CAP


# -- recall first: a car in the lane stays in the path --------------------------------------


@pytest.mark.parametrize("beyond_m", [3.0, 5.0, 10.0, 20.0])
@pytest.mark.parametrize("kph", [10, 20, 30, 40])
def test_a_car_beyond_the_end_of_a_straight_rail_stays_in_the_path(beyond_m, kph):
    straight = rail(None, last_m=32.0)
    end = 32.0 + 4.0                  # the last segment's far end
    car = [EdgePoint(1, end + beyond_m, 0.0), EdgePoint(2, end + beyond_m + 0.3, 0.6)]
    ids = edge_ids(straight + car, kph * KPH)
    assert 1 not in ids and 2 not in ids
    # The rail is a road's edge all the same: the chain ran, it did not take the car.
    assert any(p.track_id in ids for p in straight)


@pytest.mark.parametrize("kph", [10, 40])
def test_a_queue_beyond_the_rail_s_end_is_no_continuation_of_it(kph):
    """Two more stopped cars straight on behind the first: a line into the lane and then
    straight on is no road's edge (the turn in would be tighter than a road's)."""
    straight = rail(None, last_m=32.0)
    cars = [EdgePoint(i, 36.0 + 5.0 + 6.0 * i, 0.0) for i in range(1, 4)]
    ids = edge_ids(straight + cars, kph * KPH)
    assert not any(c.track_id in ids for c in cars)


@pytest.mark.parametrize("d", [-0.9, 0.0, 0.9])
def test_a_car_in_the_lane_beside_a_straight_rail_stays_in_the_path(d):
    straight = rail(None, last_m=60.0)
    car = EdgePoint(1, 30.5, d)
    ids = edge_ids([*straight, car], 30 * KPH)
    assert car.track_id not in ids
    assert len(ids) >= 8               # the rail is the edge


# -- a bending rail is the road's edge ----------------------------------------------------


@pytest.mark.parametrize(("radius", "kph"), [(50.0, 50), (-50.0, 50), (100.0, 60),
                                              (-100.0, 30), (50.0, 20)])
def test_a_bending_rail_s_segments_ahead_are_out_of_the_path(radius, kph):
    pts = rail(radius)
    ahead = in_path(pts)
    assert ahead, "the rail must cross the straight path for this test"
    ids = edge_ids(pts, kph * KPH)
    assert all(p.track_id in ids for p in ahead)
    assert "road edge" in ids[ahead[0].track_id]


def test_a_bend_tighter_than_a_driver_takes_at_the_speed_is_no_road_edge():
    # A 25 m bend: 4.9 m/s^2 sideways at 40 km/h, a road's edge; 7.7 m/s^2 at 50 km/h,
    # a line into the path that is not the road the ego is on.
    pts = rail(25.0)
    ahead = in_path(pts)
    assert ahead
    assert all(p.track_id in edge_ids(pts, 40 * KPH) for p in ahead)
    ids = edge_ids(pts, 50 * KPH)
    assert not any(p.track_id in ids for p in ahead)


def test_a_line_that_starts_in_the_path_or_too_far_is_no_edge():
    # Stationary returns in a line in the lane (a queue of stopped cars) start in the path.
    queue = [EdgePoint(i, 10.0 + 5.0 * i, 0.0) for i in range(6)]
    assert edge_ids(queue, 30 * KPH) == {}
    # A rail first seen beyond start_range_m is not trusted as the edge.
    far = rail(50.0, first_m=28.0, curve_start_m=30.0)
    assert edge_ids(far, 30 * KPH) == {}
    # A line across the road ahead starts beside the path but does not run along it.
    across = [EdgePoint(i, 15.0 + 0.5 * i, -3.0 + 1.5 * i) for i in range(5)]
    assert edge_ids(across, 30 * KPH) == {}


def test_a_single_stationary_point_or_a_short_chain_is_nothing():
    assert road_edges([EdgePoint(1, 10.0, -2.6)], HALF, 0.0, 10.0, S, CAP) == []
    two = [EdgePoint(1, 10.0, -2.6), EdgePoint(2, 14.0, -2.6)]
    assert road_edges(two, HALF, 0.0, 10.0, S, CAP) == []
    # Three make a chain, but its last members_after have nothing beyond them.
    three = [*two, EdgePoint(3, 18.0, -2.6)]
    assert set(edge_ids(three, 10.0)) == {1}


def test_a_gap_longer_than_the_spacing_ends_the_chain():
    pts = rail(50.0)
    gap = [p for p in pts if not 12.0 <= p.s_m <= 24.0]
    ids = edge_ids(gap, 50 * KPH)
    assert not any(p.track_id in ids for p in in_path(gap))


def test_two_missed_segments_in_a_row_do_not_break_the_chain():
    """A run's first radar cycles: the tracker has confirmed some segments and not yet
    the two between them (a 12 m gap)."""
    pts = rail(-100.0, curve_start_m=30.0, first_m=5.0)
    gap = [p for p in pts if not 25.0 <= p.s_m <= 30.0]
    widest = max(b.s_m - a.s_m for a, b in itertools.pairwise(gap))
    assert widest == pytest.approx(12.0, abs=0.2)
    ids = edge_ids(gap, 50 * KPH)
    assert in_path(gap) and all(p.track_id in ids for p in in_path(gap)[:-2])


# -- the kinematic rule and the core ------------------------------------------------------


def stationary(p: EdgePoint, v: float) -> RadarTrack:
    return track(tid=p.track_id, x=p.s_m, y=p.d_m, vx=-v)


def test_the_core_keeps_a_bend_s_rail_out_of_the_path_and_says_why():
    v = 50 * KPH
    pts = rail(50.0)
    ahead = in_path(pts)
    on = Drive()
    off = Drive(road_edge={"enabled": False})
    # Close enough that the rail's segment in the straight path needs a brake.
    near = [stationary(EdgePoint(p.track_id, p.s_m - 12.0, p.d_m), v) for p in pts
            if p.s_m > 12.5]
    res_off = off.step(v, *near)
    assert res_off.command.decision is Decision.BRAKE
    res = on.step(v, *near)
    assert res.command.decision is Decision.NONE
    by_id = {t.track_id: t for t in res.targets.targets}
    for p in ahead:
        tgt = by_id[p.track_id]
        assert not tgt.in_path
        assert "road's edge" in tgt.reason
    assert on.core.road_edge_targets >= 1
    assert off.core.road_edge_targets == 0
    assert any(t.gate_detail.get(ROAD_EDGE) == 1.0 for t in res.targets.targets)


def test_the_core_brakes_for_a_car_beyond_a_straight_rail_s_end():
    v = 30 * KPH
    # The rail's returns every 3 m from 2 m to 11 m (its end about 14 m), the car 18 m
    # ahead: TTC 2.2 s.
    straight = rail(None, first_m=2.0, last_m=11.0, step_m=3.0)
    car = EdgePoint(1, 18.0, 0.1)
    drive = Drive()
    res = drive.step(v, *[stationary(p, v) for p in [*straight, car]])
    assert res.command.decision is Decision.BRAKE
    by_id = {t.track_id: t for t in res.targets.targets}
    assert by_id[1].in_path and "road's edge" not in by_id[1].reason
