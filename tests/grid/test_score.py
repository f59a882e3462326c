"""The grid's scoring on synthetic timelines: first WARNING and BRAKE with their TTC, the
reaction from the first in-reach moment to BRAKE and to 50 %, the lag past the BRAKE
bound, the points, false activations, a family's sums, the sensor floor from a
configuration, and a candidate's differences."""

import math

import pytest

from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.tools.grid.lockstep import LoopConfig
from aeb_radar_camera.tools.grid.score import (
    Reach,
    actuator_half_s,
    case_points,
    failed_case,
    family_scores,
    miss_reason,
    score_case,
    sensor_floor,
    shadow_diff,
)
from aeb_radar_camera.tools.messages import ObjectKind
from aeb_radar_camera.tools.sim.scenario import ScenarioKind
from aeb_radar_camera.tools.sim.verdict import Sample, judge
from aeb_radar_camera.tools.sim.world import Collision

REACH = Reach(range_m=25.0, brake_ttc_s=3.5)
KPH = 1 / 3.6


def approach(v_kph: float, gap0_m: float, brake_at_s: float | None, *, warn_at_s=None,
             dt=0.01, decel=8.0, until_s=12.0, half_after_s=0.1) -> list[Sample]:
    """A stationary object `gap0_m` ahead, the ego at `v_kph`, braking at `decel` from
    `brake_at_s` (the actuator at 100 % `half_after_s` after the command reaches it)."""
    out: list[Sample] = []
    v, x, i = v_kph * KPH, 0.0, 0
    while i * dt <= until_s:
        t = round(i * dt, 6)
        gap = gap0_m - x
        decision = "NONE"
        if warn_at_s is not None and t >= warn_at_s:
            decision = "WARNING"
        braking = brake_at_s is not None and t >= brake_at_s
        if braking:
            decision = "BRAKE"
        position = (100.0 if braking and t >= brake_at_s + half_after_s
                    else 20.0 if braking else 0.0)
        out.append(Sample(t, x, v, gap, gap / v if v > 0 else None, decision,
                          "BRAKING" if braking else "ARMED", 100.0 if braking else 0.0,
                          position))
        if gap <= 0 or (v == 0 and braking):
            break
        if braking and t >= brake_at_s + half_after_s:
            v = max(0.0, v - decel * dt)
        x += v * dt
        i += 1
    return out


def score(samples, kind=ScenarioKind.THREAT, speed=30.0, collision=None, config="fusion",
          family="CCRs"):
    verdict = judge("case", kind, samples, collision)
    return score_case(samples, verdict, REACH, name="case", family=family, group="euro_ncap",
                      config=config, speed_kph=speed, params={"offset": 0.0}, seed=0)


def test_an_avoided_case_has_its_first_warning_brake_and_reaction_times():
    # 30 km/h, 40 m ahead: in reach (25 m) after 1.8 s, TTC 3.5 s (the bound) at 29.2 m,
    # already inside reach; WARNING at 2.5 s, BRAKE at 3.0 s
    s = score(approach(30.0, 40.0, 3.0, warn_at_s=2.5))
    assert s.passed and not s.collision and s.avoided and s.points == 1.0
    assert s.first_warning_t_s == pytest.approx(2.5)
    assert s.first_warning_ttc_s == pytest.approx((40.0 - 2.5 * 30 * KPH) / (30 * KPH), abs=0.02)
    assert s.first_brake_t_s == pytest.approx(3.0)
    assert s.first_brake_ttc_s == pytest.approx((40.0 - 3.0 * 30 * KPH) / (30 * KPH), abs=0.02)
    assert s.in_reach_t_s == pytest.approx(15.0 / (30 * KPH), abs=0.011)
    assert s.due_t_s == s.in_reach_t_s           # TTC 3 s < 3.5 s when it comes in reach
    assert s.reaction_brake_s == pytest.approx(3.0 - s.in_reach_t_s)
    assert s.reaction_half_s == pytest.approx(3.1 - s.in_reach_t_s)
    assert s.lag_brake_s == s.reaction_brake_s


def test_the_lag_counts_from_the_brake_bound_not_from_reach():
    # 10 km/h: in reach at 25 m (TTC 9 s), the bound (3.5 s) only at 9.7 m
    s = score(approach(10.0, 30.0, 7.8), speed=10.0)
    assert s.in_reach_t_s == pytest.approx(5.0 / (10 * KPH), abs=0.011)
    bound_t = (30.0 - 3.5 * 10 * KPH) / (10 * KPH)
    assert s.due_t_s == pytest.approx(bound_t, abs=0.011)
    assert s.lag_brake_s == pytest.approx(7.8 - bound_t, abs=0.011)
    assert s.reaction_brake_s is not None and s.reaction_brake_s > s.lag_brake_s


def test_a_brake_before_reach_is_a_negative_reaction():
    s = score(approach(30.0, 30.0, 0.2))       # braked at 27.5 m, before the 25 m reach
    assert s.reaction_brake_s is None or s.reaction_brake_s < 0


def test_a_collision_scores_the_speed_taken_off():
    samples = approach(50.0, 22.0, 0.6)
    hit = Collision(samples[-1].t_s, 0, ObjectKind.CAR, 20 * KPH, 20 * KPH)
    s = score(samples, speed=50.0, collision=hit)
    assert s.collision and not s.avoided and not s.passed
    assert s.impact_speed_kph == pytest.approx(20.0)
    assert s.points == pytest.approx(0.6)


def test_no_brake_no_reaction_and_no_points():
    samples = approach(40.0, 20.0, None)
    hit = Collision(samples[-1].t_s, 0, ObjectKind.CAR, 40 * KPH, 40 * KPH)
    s = score(samples, speed=40.0, collision=hit)
    assert s.points == 0.0 and s.first_brake_t_s is None
    assert s.reaction_brake_s is None and s.lag_brake_s is None and s.half_t_s is None
    assert s.in_reach_t_s == 0.0                # in reach from the start


def test_a_no_threat_case_scores_its_false_activations():
    quiet = [Sample(t / 10, t, 8.0, None, None, "NONE", "ARMED", 0.0, 0.0) for t in range(50)]
    s = score(quiet, ScenarioKind.NO_THREAT, family="plate")
    assert s.passed and s.points == 1.0 and s.false_activations == 0
    braked = [Sample(t / 10, t, 8.0, None, None, "BRAKE" if 10 <= t < 20 else "NONE",
                     "ARMED", 100.0 if 10 <= t < 20 else 0.0, 0.0) for t in range(50)]
    s = score(braked, ScenarioKind.NO_THREAT, family="plate")
    assert not s.passed and s.points == 0.0 and s.false_activations == 1
    assert s.first_brake_t_s == pytest.approx(1.0)
    assert s.reaction_brake_s is None          # nothing to react to


def test_points_of_a_threat_case_never_go_negative():
    samples = approach(10.0, 5.0, None)
    v = judge("x", ScenarioKind.THREAT, samples,
              Collision(1.0, 0, ObjectKind.CAR, 12 * KPH, 12 * KPH))
    assert case_points(ScenarioKind.THREAT, 10.0, v) == 0.0


def test_a_family_sums_its_cases_per_configuration():
    a = score(approach(30.0, 40.0, 3.0))
    b_samples = approach(50.0, 22.0, 0.6)
    b = score(b_samples, speed=50.0,
              collision=Collision(1.0, 0, ObjectKind.CAR, 20 * KPH, 20 * KPH))
    c = score(approach(30.0, 40.0, 2.5), config="paper")
    err = failed_case(name="e", family="CCRs", group="euro_ncap", kind=ScenarioKind.THREAT,
                      config="fusion", speed_kph=60.0, params={}, seed=0, error="boom")
    fams = {(f.family, f.config): f for f in family_scores([a, b, c, err])}
    f = fams[("CCRs", "fusion")]
    assert (f.cases, f.avoided, f.collisions, f.errors) == (3, 1, 1, 1)
    assert f.points == pytest.approx(1.6)
    assert f.score_pct == pytest.approx(160 / 3)
    assert f.impact_speeds_kph == [pytest.approx(20.0)]
    assert len(f.reaction_brake_s) == 2
    assert fams[("CCRs", "paper")].cases == 1
    d = f.as_dict()
    assert d["max_impact_kph"] == 20.0 and d["errors"] == 1


def test_the_sensor_floor_comes_from_the_configuration():
    cfg = LoopConfig.load(DEPLOY / "fusion.toml")
    floor = sensor_floor(cfg)
    lo, hi = cfg.loop.radar_period_s
    assert floor.confirm_cycles == cfg.radar.tracker.confirm_hits == 3
    assert floor.radar_cycle_s == pytest.approx((lo + hi) / 2)
    assert floor.frame_period_s == pytest.approx(1 / 30)
    expected = (3 * (lo + hi) / 2 + 1 / 30
                + (cfg.delays.radar_to_brake_ns + cfg.delays.camera_frame_ns) / 1e9)
    assert floor.brake_s == pytest.approx(expected)
    assert floor.half_s - floor.brake_s == pytest.approx(0.15 * math.log(2))
    assert "3 x 74 ms" in floor.describe()


def test_the_actuator_half_time_depends_on_the_level():
    assert actuator_half_s(100.0, 0.15) == pytest.approx(0.15 * math.log(2))
    assert actuator_half_s(60.0, 0.15) == pytest.approx(0.15 * math.log(6))
    assert actuator_half_s(50.0) == math.inf
    with pytest.raises(ValueError):
        actuator_half_s(100.0, 0.0)


def test_a_candidates_differences():
    pairs = [(0.1, "NONE", "NONE"), (0.2, "NONE", "WARNING"), (0.3, "WARNING", "BRAKE"),
             (0.4, "BRAKE", "BRAKE")]
    s = shadow_diff(pairs)
    assert (s.cycles, s.differing) == (4, 2)
    assert s.first_t_s == 0.2 and s.first == "NONE -> WARNING"
    assert (s.primary_brake_t_s, s.candidate_brake_t_s) == (0.4, 0.3)
    same = shadow_diff([(0.1, "NONE", "NONE")])
    assert same.differing == 0 and same.first_t_s is None


def test_an_empty_timeline_is_an_error():
    v = judge("x", ScenarioKind.THREAT, [Sample(0.0, 0.0, 1.0, None, None, "", "", 0.0, 0.0)],
              None)
    with pytest.raises(ValueError, match="no samples"):
        score_case([], v, REACH, name="x", family="CCRs", group="g", config="c",
                   speed_kph=10.0, params={}, seed=0)


def test_why_a_collision_was_not_avoided():
    late = score(approach(40.0, 20.0, 0.5), speed=40.0,
                 collision=Collision(1.0, 0, ObjectKind.CAR, 20 * KPH, 20 * KPH))
    assert late.why.startswith("braked late (TTC ")
    rejected = "camera rejected (TTC_eff 1.20 s < 2.5 s); density 0.4"
    reasons = [(0.1 * i, ["TTC_eff 5.00 s >= 4 s"] if i < 30 else [rejected, "range 30 m"])
               for i in range(50)]
    assert miss_reason(reasons, 5.0, None, False) == (
        "the camera check rejected it (20 of 20 cycles in the last 2 s)")
    assert miss_reason([(0.1 * i, []) for i in range(50)], 5.0, None, False).startswith(
        "no confirmed track (20 of 20")
    warned = [(4.0, ["verified, TTC_eff 3.07 s < 4 s"])]
    assert miss_reason(warned, 5.0, None, False).startswith("verified, TTC not under")
    assert miss_reason([], 5.0, None, False) == "no radar cycle before the impact"
    # the kinematic rule's reasons
    aside = [(4.0, ["out of path (s 7.3 m, offset -3.72 m, limit 1.2 m, straight path)"])]
    assert miss_reason(aside, 5.0, None, False).startswith("outside the predicted path")
    early = [(4.0, ["no stage reached: needs 0.41 m/s^2, TTC 6.26 s, target accel -0.3"])]
    assert miss_reason(early, 5.0, None, False).startswith("verified, no braking stage")
    avoided = score(approach(30.0, 40.0, 3.0))
    assert avoided.why == ""


def test_the_kinematic_rules_reach_and_due_follow_its_range_gate_and_first_stage():
    reach = Reach.of(LoopConfig.load(DEPLOY / "fusion.toml"))
    assert reach.brake_decel_mps2 is not None and reach.range_base_m is not None
    # 50 km/h: the gate reaches 15 + 3.5 x 13.9 = 63.6 m; a stop needs 3 m/s^2 (the
    # partial stage) from about 32.3 + 1 + 6.25 m, before the TTC falls to 2.2 s (30.6 m).
    v = 50 * KPH
    assert reach.reach_m(v) == pytest.approx(15.0 + 3.5 * v)
    samples = approach(50.0, 80.0, None, until_s=5.0)
    s = score_case(samples, judge("case", ScenarioKind.THREAT, samples, None), reach,
                   name="case", family="CCRs", group="euro_ncap", config="fusion",
                   speed_kph=50.0, params={}, seed=0)
    assert s.in_reach_t_s == pytest.approx((80.0 - 15.0 - 3.5 * v) / v, abs=0.011)
    need_gap = v * v / (2 * 3.0) + 1.0 + 0.45 * v
    assert s.due_t_s is not None and s.due_t_s == pytest.approx((80.0 - need_gap) / v, abs=0.011)
    assert (80.0 - s.due_t_s * v) / v > 2.2          # due on the deceleration, not the TTC
