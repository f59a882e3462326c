"""Roads of constant curvature: road coordinates, the ego following the lane (pose, yaw
rate = v / R), the vehicle frame the sensors see, and the ground truth along the curved
path (an object beside the road on the outside of a bend is not a threat)."""

import math

import numpy as np
import pytest

from aeb_radar_camera.tools.messages import ObjectKind, RoadGeometry
from aeb_radar_camera.tools.sim.road import Pose, Road
from aeb_radar_camera.tools.sim.scenario import (
    EgoSpec,
    Motion,
    RoadSpec,
    Scenario,
    ScenarioKind,
    SceneObject,
)
from aeb_radar_camera.tools.sim.world import World

R = 50.0
BEND = RoadSpec(curve_start_m=10.0, radius_m=R)


def scenario(*objects: SceneObject, road: RoadSpec = BEND, speed_kph: float = 36.0
             ) -> Scenario:
    return Scenario(name="t", kind=ScenarioKind.THREAT, ego=EgoSpec(speed_kph=speed_kph),
                    object=objects, road=road)


@pytest.mark.parametrize("radius", [50.0, -50.0, 300.0, -1000.0])
def test_road_coordinates_round_trip_and_follow_the_arc(radius):
    road = Road(RoadGeometry(curve_start_m=20.0, radius_m=radius))
    s = np.linspace(0.0, 120.0, 61)
    for d in (-9.5, -2.6, 0.0, 3.5):
        xy = road.to_world(s, np.full_like(s, d))
        s2, d2 = road.to_road(xy[:, 0], xy[:, 1])
        assert np.allclose(s2, s, atol=1e-9) and np.allclose(d2, d, atol=1e-9)
    # On the arc the lane centre keeps its distance from the bend's centre.
    xy = road.to_world(s[s > 20.0], np.zeros((s > 20.0).sum()))
    assert np.allclose(np.hypot(xy[:, 0] - 20.0, xy[:, 1] - radius), abs(radius))
    assert road.heading_at(20.0 + abs(radius) * math.pi / 4) == pytest.approx(
        math.copysign(math.pi / 4, radius))
    assert road.heading_at(5.0) == 0.0 and road.curvature_at(30.0) == pytest.approx(1 / radius)


def test_a_straight_road_is_the_old_world_frame():
    road = Road()
    xy = road.to_world(np.array([12.0, 40.0]), np.array([-1.0, 2.5]))
    assert xy.tolist() == [[12.0, -1.0], [40.0, 2.5]]
    assert road.pose_at(7.0) == Pose(7.0, 0.0, 0.0)


def test_the_ego_follows_the_lane_with_yaw_rate_speed_over_radius():
    world = World(scenario(SceneObject(ObjectKind.CAR, 200.0, 0.0)))
    v = 10.0
    assert world.yaw_rate_dps() == 0.0                  # still on the straight
    headings = []
    for _ in range(400):                                 # 4 s at 10 m/s: 30 m into the bend
        world.step(0.01, 0.0)
        pose = world.ego_pose()
        if world.ego.s_m > 10.0:
            # The radar on the lane centre: R from the bend's centre, heading its tangent.
            assert math.hypot(pose.x_m - 10.0, pose.y_m - R) == pytest.approx(R, abs=1e-6)
            headings.append(pose.heading_rad)
    assert world.yaw_rate_dps() == pytest.approx(math.degrees(v / R))
    assert headings[-1] == pytest.approx((world.ego.s_m - 10.0) / R)
    assert world.ego.s_m == pytest.approx(40.0)


def test_the_vehicle_frame_turns_with_the_ego():
    """A car on the lane centre 30 m further along the arc is ahead and to the left of
    the ego in its own frame (the chord of the arc), a parked car beside the road on the
    outside of the bend is straight ahead, and a straight road is the world frame."""
    ahead = SceneObject(ObjectKind.CAR, 50.0 + 30.0, 0.0)
    outside = SceneObject(ObjectKind.CAR, 50.0 + 17.0, -3.0)
    world = World(scenario(ahead, outside))
    world.step(5.0, 0.0)                                  # station 50 m: 40 m into the bend
    car, parked = world.vehicle_bodies()
    chord = 2 * R * math.sin(30.0 / (2 * R))
    assert math.hypot(car.x_m, car.y_m) == pytest.approx(chord, abs=1e-6)
    assert car.y_m == pytest.approx(R * (1 - math.cos(30.0 / R)), abs=1e-6)
    assert car.yaw_deg == pytest.approx(math.degrees(30.0 / R))
    phi = 17.0 / R
    assert (parked.x_m, parked.y_m) == pytest.approx(
        ((R + 3.0) * math.sin(phi), R - (R + 3.0) * math.cos(phi)), abs=1e-6)
    assert abs(parked.y_m) < 0.1                          # in the straight line ahead
    straight = World(scenario(ahead, outside, road=RoadSpec()))
    straight.step(5.0, 0.0)
    assert [(b.x_m, b.y_m) for b in straight.vehicle_bodies()] == [(30.0, 0.0), (17.0, -3.0)]


def test_ground_truth_runs_along_the_bend():
    """In the lane on the arc: a threat with the gap along the road; beside the road on
    the outside (straight ahead of the ego): no threat, never hit."""
    in_lane = SceneObject(ObjectKind.CAR, 20.0 + 32.2, 0.0)        # rear 30 m ahead
    outside = SceneObject(ObjectKind.BOX, 20.0 + 16.0, -3.5)
    world = World(scenario(outside, in_lane))
    world.step(2.0, 0.0)                                   # 10 m into the bend, 10 m/s
    threat = world.threat()
    assert threat is not None and threat.object_index == 1
    # The rigid car's rear corners sit a few cm off its centre line's station.
    assert threat.gap_m == pytest.approx(30.0, abs=0.1)
    assert threat.ttc_s == pytest.approx(3.0, abs=0.01)
    assert world.in_path_gap() == pytest.approx(threat.gap_m)
    box = world.vehicle_bodies()[0]
    assert box.x_m > 0 and abs(box.y_m) < 2.0             # in the straight line ahead
    only_outside = World(scenario(outside))
    while not only_outside.passed_everything():
        only_outside.step(0.02, 0.0)
        assert only_outside.threat() is None
    assert only_outside.collision is None


def test_a_lead_car_follows_its_lane_through_the_bend_and_a_crossing_one_crosses_it():
    lead = SceneObject(ObjectKind.CAR, 20.0, 0.0, motion=Motion(speed_mps=8.0))
    walker = SceneObject(ObjectKind.PEDESTRIAN, 60.0, -4.0, 90.0,
                         motion=Motion(speed_mps=1.5, heading_deg=90.0))
    world = World(scenario(lead, walker, speed_kph=18.0))
    world.step(4.0, 0.0)
    pose = Road(BEND).pose_at(20.0 + 32.0)
    car, ped = world.bodies()
    assert (car.x_m, car.y_m) == pytest.approx((pose.x_m, pose.y_m), abs=1e-6)
    assert math.degrees(math.atan2(car.vy_mps, car.vx_mps)) == pytest.approx(
        math.degrees(pose.heading_rad))
    assert math.hypot(car.vx_mps, car.vy_mps) == pytest.approx(8.0)
    s, d = Road(BEND).to_road(np.array([ped.x_m]), np.array([ped.y_m]))
    assert s[0] == pytest.approx(60.0) and d[0] == pytest.approx(-4.0 + 6.0)
    # The lead pulls away along the lane, the walker has crossed it: nothing to hit.
    assert world.threat() is None
    assert world.in_path_gap() == pytest.approx(52.0 - 2.2 - 20.0, abs=0.1)


def test_a_road_tighter_than_50_m_or_unknown_road_fields_are_refused(tmp_path):
    from aeb_radar_camera.common.config.loader import ConfigError
    from aeb_radar_camera.tools.sim.scenario import load_scenario

    for road, match in (("radius_m = 40.0", "at least 50 m"), ("radius = 80.0", "radius")):
        f = tmp_path / "bad.toml"
        f.write_text(f'name = "bad"\nkind = "threat"\n[ego]\nspeed_kph = 30.0\n[road]\n{road}\n'
                     '[[object]]\nkind = "car"\nx_m = 20.0\n')
        with pytest.raises(ConfigError, match=match):
            load_scenario(f)
