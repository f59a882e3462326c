"""The simulator's pure parts: scenario files, ego and object kinematics, collisions,
ground truth and verdicts."""

import math

import msgspec
import pytest

from aeb_radar_camera.common.config.loader import ConfigError, parse_config
from aeb_radar_camera.tools.messages import ObjectKind
from aeb_radar_camera.tools.sim.scenario import (
    EgoSpec,
    Motion,
    Scenario,
    ScenarioKind,
    SceneObject,
    all_scenarios,
    find_scenario,
    load_scenario,
)
from aeb_radar_camera.tools.sim.verdict import Sample, judge, summary_line
from aeb_radar_camera.tools.sim.world import World

DT = 0.005


def scenario(*objects: SceneObject, speed_kph: float = 30.0, **ego) -> Scenario:
    return Scenario(name="t", kind=ScenarioKind.THREAT, ego=EgoSpec(speed_kph=speed_kph, **ego),
                    object=objects)


def drive(world: World, seconds: float, position_pct: float = 0.0) -> None:
    for _ in range(round(seconds / DT)):
        world.step(DT, position_pct)


def run_without_brake(sc: Scenario) -> World:
    world = World(sc)
    while world.t_s < sc.duration_s and world.collision is None and not world.passed_everything():
        world.step(DT, 0.0)
    return world


SCENARIOS = all_scenarios()


def test_the_library_covers_every_object_kind_speed_and_scenario_type():
    loaded = [load_scenario(p) for p in SCENARIOS]
    kinds = {o.kind for s in loaded for o in s.object}
    assert kinds == set(ObjectKind)
    speeds = {s.ego.speed_kph for s in loaded}
    assert min(speeds) == 10 and max(speeds) == 30
    assert {s.kind for s in loaded} == set(ScenarioKind)
    assert any(len(s.object) >= 3 for s in loaded)                       # several at once
    assert any(o.motion and o.motion.trigger_gap_m for s in loaded for o in s.object)
    names = [p.stem for p in SCENARIOS]
    assert names == [s.name for s in loaded]   # file name = scenario name


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_threats_collide_without_braking_and_no_threats_do_not(path):
    sc = load_scenario(path)
    world = run_without_brake(sc)
    if sc.kind is ScenarioKind.THREAT:
        assert world.collision is not None, "a threat scenario must be a threat"
        assert world.collision.ego_speed_mps == pytest.approx(sc.ego.speed_kph / 3.6)
    else:
        assert world.collision is None
        assert world.passed_everything(), "the ego drives past every object"


def test_invalid_scenarios_name_the_field(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\nkind = "threat"\n[ego]\nspeed_kph = 70.0\n'
                   '[[object]]\nkind = "car"\nx_m = 20.0\n')
    with pytest.raises(ConfigError, match=r"\$\.ego\.speed_kph"):
        load_scenario(bad)
    with pytest.raises(ConfigError, match="ahead of the ego"):
        parse_config({"name": "x", "kind": "threat", "ego": {"speed_kph": 20},
                      "object": [{"kind": "box", "x_m": -1.0}]}, Scenario)
    with pytest.raises(ConfigError, match="truck"):
        parse_config({"name": "x", "kind": "threat", "ego": {"speed_kph": 20},
                      "object": [{"kind": "truck", "x_m": 10.0}]}, Scenario)
    with pytest.raises(ConfigError, match="no scenario 'nope'"):
        find_scenario("nope")
    assert find_scenario("stationary_car_30kph").is_file()


def test_deceleration_follows_the_brake_position_through_the_lag():
    world = World(scenario(SceneObject(ObjectKind.CAR, 200.0), brake_lag_s=0.2,
                           max_decel_mps2=6.0))
    drive(world, 0.2, 50.0)       # one time constant at half brake
    assert world.ego.decel_mps2 == pytest.approx(3.0 * (1 - math.exp(-1)), rel=0.02)
    drive(world, 2.0, 50.0)
    assert world.ego.decel_mps2 == pytest.approx(3.0, rel=0.01)
    drive(world, 1.0, 0.0)         # released: the deceleration decays, the ego coasts
    assert world.ego.decel_mps2 == pytest.approx(3.0 * math.exp(-5), rel=0.02)
    v = world.ego.speed_mps
    drive(world, 1.0, 0.0)
    assert v - 0.01 < world.ego.speed_mps <= v   # coasts (residual lag), never speeds up


def test_full_brake_without_lag_stops_in_v_squared_over_2a():
    world = World(scenario(SceneObject(ObjectKind.CAR, 200.0), brake_lag_s=0.0,
                           max_decel_mps2=6.0))
    v0 = world.ego.speed_mps
    drive(world, 3.0, 100.0)
    assert world.ego.speed_mps == 0.0
    assert world.ego.x_m == pytest.approx(v0 ** 2 / (2 * 6.0), abs=0.01)


def test_collision_reports_impact_speed_and_stops_the_world():
    world = World(scenario(SceneObject(ObjectKind.BOX, 10.3), speed_kph=18.0))
    drive(world, 3.0)
    assert world.collision is not None
    assert world.collision.kind is ObjectKind.BOX
    assert world.collision.ego_speed_mps == pytest.approx(5.0)
    # The ego's front reached the box's rear face (x = 10.0) at 5 m/s: t = 2.0 s.
    assert world.collision.t_s == pytest.approx(2.0, abs=2 * DT)
    x = world.ego.x_m
    drive(world, 1.0)
    assert world.ego.x_m == x


def test_ground_truth_gap_and_ttc_to_the_nearest_in_path_object():
    world = World(scenario(SceneObject(ObjectKind.CAR, 32.2, 0.0),        # rear at 30 m
                           SceneObject(ObjectKind.BOX, 20.3, 3.0),        # beside the path
                           SceneObject(ObjectKind.PEDESTRIAN, 40.0, 0.5), speed_kph=36.0))
    threat = world.threat()
    assert threat is not None and threat.object_index == 0
    assert threat.gap_m == pytest.approx(30.0)
    assert threat.ttc_s == pytest.approx(3.0)


def test_ttc_counts_objects_that_will_cross_into_the_path():
    crossing = SceneObject(ObjectKind.PEDESTRIAN, 30.0, -4.5,
                           motion=Motion(speed_mps=1.4, heading_deg=90.0))
    away = SceneObject(ObjectKind.PEDESTRIAN, 12.0, -2.0,
                       motion=Motion(speed_mps=1.4, heading_deg=-90.0))
    world = World(scenario(crossing, away, speed_kph=36.0))
    assert world.in_path_gap() is None          # nobody in the path yet
    threat = world.threat()
    assert threat is not None and threat.object_index == 0
    # Its near face (x 29.825) meets the ego's front at 2.98 s; by then it has walked
    # into the ego's 1.8 m width (from 2.375 s).
    assert threat.ttc_s == pytest.approx(2.9825)
    assert threat.gap_m == pytest.approx(29.825)


def test_a_moving_object_starts_when_the_ego_comes_within_its_trigger_gap():
    walker = SceneObject(ObjectKind.PEDESTRIAN, 30.0, -5.0, motion=Motion(
        speed_mps=1.5, heading_deg=90.0, trigger_gap_m=20.0, distance_m=3.0))
    world = World(scenario(walker, speed_kph=36.0))       # 10 m/s: trigger at t = 1 s
    drive(world, 0.9)
    assert world.bodies()[0].y_m == -5.0 and world.bodies()[0].vy_mps == 0.0
    drive(world, 0.2)
    body = world.bodies()[0]
    assert body.vy_mps == pytest.approx(1.5) and body.y_m > -5.0
    drive(world, 3.0)                                     # walked its 3 m, then stands
    body = world.bodies()[0]
    assert body.y_m == pytest.approx(-2.0) and body.vy_mps == 0.0
    assert world.collision is None


def test_negative_time_step_is_refused():
    with pytest.raises(ValueError, match="negative"):
        World(scenario(SceneObject(ObjectKind.CAR, 20.0))).step(-0.1, 0.0)


def samples(decisions: str, positions: list[float], speeds: list[float] | None = None):
    """One sample per 0.1 s; decisions as letters: N(ONE) W(ARNING) B(RAKE)."""
    names = {"N": "NONE", "W": "WARNING", "B": "BRAKE", "-": ""}
    speeds = speeds or [10.0] * len(positions)
    out, x = [], 0.0
    for i, (d, p, v) in enumerate(zip(decisions, positions, speeds, strict=True)):
        x += v * 0.1
        out.append(Sample(i * 0.1, x, v, 20.0 - x, (20.0 - x) / v if v else None, names[d],
                          "ARMED", 100.0 if d == "B" else 0.0, p))
    return out


def test_verdict_of_an_avoided_threat():
    s = samples("NNWWBBBBBN", [0, 0, 0, 0, 0, 30, 80, 100, 100, 100],
                [10, 10, 10, 10, 10, 9, 6, 3, 0, 0])
    v = judge("x", ScenarioKind.THREAT, s, None)
    assert v.passed and v.outcome == "avoided (stopped)"
    assert v.first_brake_t_s == pytest.approx(0.4)
    assert v.first_brake_ttc_s == pytest.approx(s[4].ttc_s)
    assert v.actuation_t_s == pytest.approx(0.5)
    assert v.stopping_distance_m == pytest.approx(s[8].ego_x_m - s[4].ego_x_m)
    assert v.min_gap_m == pytest.approx(min(x.gap_m for x in s))
    assert v.brake_activations == 1 and v.false_activations == 0 and v.warnings == 1
    assert "PASS" in summary_line(v)


def test_verdict_of_a_collision_and_of_false_activations():
    from aeb_radar_camera.tools.sim.world import Collision

    s = samples("NNNNN", [0] * 5)
    hit = Collision(0.4, 0, ObjectKind.CAR, 25 / 3.6, 25 / 3.6)
    v = judge("x", ScenarioKind.THREAT, s, hit)
    assert not v.passed and v.outcome == "collision at 25.0 km/h"
    assert v.impact_speed_kph == pytest.approx(25.0)
    assert v.first_brake_t_s is None and "FAIL" in summary_line(v)
    s = samples("NBBNNBNN", [0] * 8)
    v = judge("y", ScenarioKind.NO_THREAT, s, None)
    assert not v.passed and v.false_activations == 2 and v.outcome == "2 false activations"
    v = judge("z", ScenarioKind.NO_THREAT, samples("NNWN", [0] * 4), None)
    assert v.passed and v.outcome == "no activation" and v.warnings == 1
    with pytest.raises(ValueError):
        judge("e", ScenarioKind.THREAT, [], None)


def test_scenarios_round_trip_through_msgspec():
    sc = load_scenario(SCENARIOS[0])
    assert msgspec.convert(msgspec.to_builtins(sc), Scenario) == sc
