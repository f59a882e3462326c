"""The kinematic rule (rule = "kinematic"): the formulas, the stages, the path through a
bend, the hold at standstill, the driver's override and the degraded mode, on the pure
core."""
import math
from pathlib import Path
from typing import Any

import msgspec
import pytest

from aeb_radar_camera.common.config.fusion import FusionConfig, RuleName
from aeb_radar_camera.common.config.loader import load_config
from aeb_radar_camera.common.messages import (
    Decision,
    DriverInputs,
    EgoMotion,
    Gear,
    Header,
    RadarTrack,
)
from aeb_radar_camera.services.fusion.core import CycleResult, FusionCore
from aeb_radar_camera.services.fusion.decision import (
    LeadAcceleration,
    required_decel,
    time_to_collision,
    unseen_turn,
)
from tests.fusion.helpers import MS, T0, cycle, feed, frame, make_core, track

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
KINEMATIC = {"rule": "kinematic"}


# -- the formulas ---------------------------------------------------------------------------


def test_ttc_of_a_stationary_target_is_gap_over_speed():
    assert time_to_collision(20.0, 10.0, 0.0, 0.0) == pytest.approx(2.0)
    assert time_to_collision(20.0, 10.0, 12.0, 0.0) is None     # pulling away


def test_ttc_counts_a_braking_lead():
    # Both at 50 km/h, 20 m apart, the lead braking at 6 m/s^2: it stops after 2.31 s
    # and 16.1 m; the ego, unbraked, reaches that spot after (20 + 16.1) / 13.9 = 2.6 s.
    v = 50 / 3.6
    assert time_to_collision(20.0, v, v, 0.0) is None           # range rate alone: never
    assert time_to_collision(20.0, v, v, 6.0) == pytest.approx(
        (20.0 + v * v / 12.0) / v)
    # 12 m apart the lead still moves when the ego arrives: the quadratic's root.
    assert time_to_collision(12.0, v, v, 6.0) == pytest.approx(math.sqrt(2 * 12.0 / 6.0))


def test_required_deceleration_for_a_stationary_target_with_latency():
    # 50 km/h, 25 m: 3.86 m/s^2 with no latency (the figure), more with it.
    v = 50 / 3.6
    assert required_decel(25.0, v, 0.0, 0.0, 0.0) == pytest.approx(v * v / 50.0)
    assert v * v / 50.0 == pytest.approx(3.86, abs=0.01)
    assert required_decel(25.0, v, 0.0, 0.0, 0.45) == pytest.approx(
        v * v / (2 * (25.0 - 0.45 * v)))
    assert required_decel(5.0, v, 0.0, 0.0, 0.45) == math.inf    # gone within the latency


def test_required_deceleration_to_match_a_slower_lead():
    assert required_decel(20.0, 20.0, 10.0, 0.0, 0.0) == pytest.approx(100 / 40)
    assert required_decel(20.0, 10.0, 10.0, 0.0, 0.0) == 0.0


def test_required_deceleration_behind_a_braking_lead():
    v = 50 / 3.6
    # The lead stops first: stop behind where it stops.
    assert required_decel(12.0, v, v, 6.0, 0.0) == pytest.approx(
        v * v / (2 * (12.0 + v * v / 12.0)))
    # Without the lead's deceleration it would look like no braking is needed at all.
    assert required_decel(12.0, v, v, 0.0, 0.0) == 0.0
    # Faster than the lead, which brakes gently: match its speed while it still moves.
    need = required_decel(30.0, 20.0, 10.0, 1.0, 0.0)
    assert need == pytest.approx(1.0 + 100 / 60)


def test_lead_acceleration_is_the_filtered_derivative_of_its_speed():
    acc = LeadAcceleration(tau_s=0.3, limit_mps2=10.0)
    t, v, out = T0, 14.0, {}
    for _ in range(30):                       # 2.25 s of braking at 6 m/s^2
        out = acc.update({1: v}, t)
        t += 75 * MS
        v -= 6.0 * 0.075
    assert out[1] == pytest.approx(-6.0, abs=0.05)
    # A new track, or one back after a gap: no acceleration yet.
    assert acc.update({2: 5.0}, t) == {2: 0.0}
    assert acc.update({1: 5.0}, t + 2_000 * MS) == {1: 0.0}


def test_lead_acceleration_spike_is_clipped_and_filtered():
    acc = LeadAcceleration(tau_s=0.3, limit_mps2=10.0)
    acc.update({1: 10.0}, T0)
    out = acc.update({1: 30.0}, T0 + 75 * MS)       # a 20 m/s jump (an ID swap)
    assert 0.0 < out[1] < 10.0 * 0.25


# -- the core with the kinematic rule ---------------------------------------------------------


class Drive:
    """A kinematic core fed vehicle state and radar cycles on one clock (wall = mono +
    T0), 75 ms apart."""

    def __init__(self, core: FusionCore | None = None, **decision):
        self.core = core or make_core(decision={**KINEMATIC, **decision})
        self.t = 0
        self.seq = 0

    def vehicle(self, speed: float, yaw_dps: float = 0.0, **driver: Any) -> None:
        header = Header(seq=0, source="test", stamp_ns=T0 + self.t, pub_mono_ns=self.t)
        inputs: dict[str, Any] = dict(steering_wheel_angle_deg=0.0, steering_wheel_rate_dps=0.0,
                      accelerator_pedal_pct=20.0, kickdown=False, brake_pedal_pressed=False,
                      brake_pressure_bar=0.0, gear=Gear.DRIVE)
        inputs.update(driver)
        self.core.on_vehicle(EgoMotion(header=header, speed_mps=speed, yaw_rate_dps=yaw_dps),
                             T0 + self.t, self.t)
        self.core.on_vehicle(DriverInputs(header=header, **inputs), T0 + self.t, self.t)

    def cycle(self, *tracks: RadarTrack, dt_ms: int = 75) -> CycleResult:
        self.t += dt_ms * MS
        stamp = T0 + self.t
        res = self.core.process(cycle(*tracks, seq=self.seq, stamp_ns=stamp),
                                feed(frame(stamp)), stamp + 5 * MS, self.t + 5 * MS)
        self.seq += 1
        return res

    def step(self, speed: float, *tracks: RadarTrack, yaw_dps: float = 0.0,
             **driver) -> CycleResult:
        """Vehicle state, and a radar cycle 10 ms later; the next step 75 ms on."""
        self.vehicle(speed, yaw_dps, **driver)
        res = self.cycle(*tracks, dt_ms=10)
        self.t += 65 * MS
        return res


def ahead(x: float, v_ego: float, tid: int = 1, y: float = 0.0, lead: float = 0.0,
          vy: float = 0.0) -> RadarTrack:
    """A track ahead on a straight road, closing at ego speed - its own."""
    return track(tid=tid, x=x, y=y, vx=lead - v_ego, vy=vy)


def test_default_deploy_config_uses_the_kinematic_rule_and_the_paper_profile_the_paper():
    assert load_config(DEPLOY / "fusion.toml", FusionConfig).fusion.decision.rule \
        is RuleName.KINEMATIC
    assert load_config(DEPLOY / "fusion-paper.toml", FusionConfig).fusion.decision.rule \
        is RuleName.PAPER


@pytest.mark.parametrize("x", [75.0, 60.0, 52.0, 45.0, 38.0, 30.0, 20.0])
def test_each_stage_from_its_own_bound_at_50_kph(x):
    v = 50 / 3.6
    res = Drive().step(v, ahead(x, v))
    tgt = res.targets.targets[0]
    need = required_decel(x - 1.0, v, 0.0, 0.0, 0.45)
    assert tgt.required_decel_mps2 == pytest.approx(need, rel=1e-6)
    ttc = x / v
    assert tgt.ttc_s == pytest.approx(ttc)
    if need >= 4.5 or ttc < 1.6:
        expected = (Decision.BRAKE, 100.0)
    elif need >= 3.0 or ttc < 2.2:
        expected = (Decision.BRAKE, 50.0)
    elif need >= 2.0 or ttc < 3.0:
        expected = (Decision.WARNING, 0.0)
    else:
        expected = (Decision.NONE, 0.0)
    assert (res.command.decision, res.command.brake_level_pct) == expected
    assert tgt.brake_level_pct == (expected[1] or None)


def test_stage_bounds_in_order_at_50_kph():
    v = 50 / 3.6
    seen = []
    for x in (75.0, 60.0, 50.0, 45.0, 40.0, 35.0, 30.0, 25.0):
        res = Drive().step(v, ahead(x, v))
        seen.append((res.command.decision, res.command.brake_level_pct))
    assert seen[0] == (Decision.NONE, 0.0)
    assert (Decision.WARNING, 0.0) in seen
    assert (Decision.BRAKE, 50.0) in seen
    assert seen[-1] == (Decision.BRAKE, 100.0)
    # Never down a stage as the gap shrinks.
    order = [(d is Decision.BRAKE) * 1 + (d is not Decision.NONE) + lvl / 100 for d, lvl in seen]
    assert order == sorted(order)


def test_a_radar_point_entering_the_paths_margin_warns_for_a_cycle_before_partial_braking():
    # 60 km/h, 53 m ahead: the stop needs the partial stage (3 m/s^2). The path's margin
    # is 0.9-1.2 m from its centre.
    v = 60 / 3.6
    d = Drive()
    first = d.step(v, ahead(53.0, v, y=-1.15))
    assert (first.command.decision, first.command.brake_level_pct) == (Decision.WARNING, 0.0)
    assert "entered the path's margin this cycle" in first.targets.targets[0].reason
    second = d.step(v, ahead(53.0 - v * 0.075, v, y=-1.15))
    assert (second.command.decision, second.command.brake_level_pct) == (Decision.BRAKE, 50.0)


def test_a_radar_point_flickering_across_the_margins_edge_never_reaches_the_partial_stage():
    # An object as far beside the path as the margin is wide: its point in, out, in.
    v = 60 / 3.6
    d = Drive()
    seen = [d.step(v, ahead(53.0 - i * v * 0.075, v, y=y)).command.decision
            for i, y in enumerate((-1.15, -1.25, -1.17, -1.22, -1.18))]
    assert seen == [Decision.WARNING, Decision.NONE] * 2 + [Decision.WARNING]


@pytest.mark.parametrize(("x", "y", "level"), [(53.0, -0.5, 50.0), (25.0, -1.15, 100.0)])
def test_inside_the_vehicles_width_or_at_the_full_stage_nothing_waits(x, y, level):
    v = 60 / 3.6
    res = Drive().step(v, ahead(x, v, y=y))
    assert (res.command.decision, res.command.brake_level_pct) == (Decision.BRAKE, level)


def test_range_gate_follows_speed():
    # 30 m ahead at 60 km/h is far inside the gate (15 + 3.5 x 16.7 = 73 m); the paper's
    # 25 m gate would not look at it at all.
    v = 60 / 3.6
    assert Drive().step(v, ahead(30.0, v)).command.decision is Decision.BRAKE
    res = Drive().step(v, ahead(76.0, v))
    assert res.command.decision is Decision.NONE
    assert "outside [0.5, 73.3] m" in res.targets.targets[0].reason
    paper = make_core()
    assert paper.process(cycle(ahead(30.0, v)), feed(frame()), T0 + 5 * MS, 1) \
        .command.decision is Decision.NONE


def test_a_slowly_closing_target_inside_the_papers_3_m_still_brakes():
    # 20 km/h behind a cyclist at 15 km/h: 1.4 m/s closing, TTC 2.1 s only at 3 m. The
    # paper's 3 m near bound would drop it just as it becomes a threat.
    v, lead = 20 / 3.6, 15 / 3.6
    res = Drive().step(v, ahead(2.5, v, lead=lead))
    assert res.command.decision is Decision.BRAKE
    paper_near = Drive(kinematic={"range_min_m": 3.0}).step(v, ahead(2.5, v, lead=lead))
    assert paper_near.command.decision is Decision.NONE
    assert "outside [3, " in paper_near.targets.targets[0].reason


def test_a_braking_lead_is_braked_for_before_its_range_rate_shows_it():
    # CCRb: both at 50 km/h, 12 m apart, the lead brakes at 6 m/s^2.
    v = 50 / 3.6
    d = Drive()
    lead, gap, res = v, 12.0, None
    decisions = []
    for _ in range(6):
        res = d.step(v, ahead(gap, v, lead=lead))
        decisions.append(res.command.decision)
        lead -= 6.0 * 0.075
        gap -= (v - lead) * 0.075
    assert res is not None
    tgt = res.targets.targets[0]
    assert tgt.accel_mps2 is not None and tgt.accel_mps2 < -3.0
    assert Decision.BRAKE in decisions
    # The range rate alone (-1.5 m/s at 10.7 m): TTC 7 s, nothing.
    assert (gap / (v - lead)) > 4.0


def test_bend_outside_object_is_out_of_the_path_and_a_car_in_the_lane_in_it():
    v, radius = 30 / 3.6, 50.0
    yaw = math.degrees(v / radius)
    # A guard-rail post 3.5 m outside the left bend, 15 m along it; what the radar reports
    # for a stationary object seen from the turning ego: vx = -v + w y, vy = -w x.
    w = v / radius

    def stationary(s_m: float, d_m: float, tid: int) -> RadarTrack:
        rho = radius - d_m
        x, y = rho * math.sin(s_m / radius), radius - rho * math.cos(s_m / radius)
        return track(tid=tid, x=x, y=y, vx=-v + w * y, vy=-w * x)
    post = stationary(15.0, -3.5, 1)
    car = stationary(15.0, 0.0, 2)
    assert abs(post.y_m) < 1.2 < abs(car.y_m)   # a straight corridor: the wrong one
    res = Drive().step(v, post, car, yaw_dps=yaw)
    by_id = {t.track_id: t for t in res.targets.targets}
    assert not by_id[1].in_path and "out of path" in by_id[1].reason
    assert by_id[2].in_path and by_id[2].path_d_m == pytest.approx(0.0, abs=1e-6)
    assert by_id[2].path_s_m == pytest.approx(15.0, abs=1e-6)
    assert res.command.decision is Decision.BRAKE and res.command.track_id == 2
    assert "R 50 m left" in res.targets.path


def test_straight_corridor_in_the_bend_brakes_for_the_rail_and_misses_the_car():
    """The same bend with no vehicle state (the paper's straight corridor): the post is
    in it, the car in the lane is not."""
    v, radius = 30 / 3.6, 50.0
    w = v / radius
    rho_post = radius + 0.6
    x = rho_post * math.sin(10.0 / radius)
    y = radius - rho_post * math.cos(10.0 / radius)
    post = track(tid=1, x=x, y=y, vx=-v + w * y, vy=-w * x)
    d = Drive()
    res = d.cycle(post)                      # no vehicle state
    assert res.targets.vehicle_state
    assert res.targets.targets[0].in_path    # straight: in the corridor
    res = Drive().step(v, post, yaw_dps=math.degrees(w))
    t = res.targets.targets[0]
    assert t.in_path is False or (t.path_d_m is not None and abs(t.path_d_m) > 0.5)


def test_crossing_pedestrian_predicted_along_the_arc():
    v, radius = 20 / 3.6, 100.0
    w = v / radius
    # 15 m along a left bend, 3 m to the right of the path, walking left at 1.5 m/s
    # (over ground, across the path): in the path when the ego arrives (2.7 s).
    s, dist = 15.0, -3.0
    phi = s / radius
    rho = radius - dist
    x, y = rho * math.sin(phi), radius - rho * math.cos(phi)
    gvx, gvy = -1.5 * math.sin(phi), 1.5 * math.cos(phi)     # the path's normal there
    ped = track(tid=3, x=x, y=y, vx=gvx - v + w * y, vy=gvy - w * x)
    d = Drive()
    results = [d.step(v, ped) for _ in range(3)]      # sideways motion confirmed (2 cycles)
    tgt = results[-1].targets.targets[0]
    assert tgt.path_predicted
    assert tgt.in_path
    assert tgt.ttc_s == pytest.approx(s / v, rel=0.05)


def test_an_object_parked_beside_a_bend_does_not_walk_into_the_path():
    """Stationary on the outside of the bend: in the radar frame it moves sideways
    (vy = -w x) but over ground it stands: never predicted into the path."""
    v, radius = 40 / 3.6, 50.0
    w = v / radius
    rho = radius + 2.6
    x, y = rho * math.sin(25 / radius), radius - rho * math.cos(25 / radius)
    parked = track(tid=1, x=x, y=y, vx=-v + w * y, vy=-w * x)
    assert abs(parked.vy_mps) > 1.0
    d = Drive()
    for _ in range(4):
        res = d.step(v, parked, yaw_dps=math.degrees(w))
        assert res.command.decision is Decision.NONE
        assert not res.targets.targets[0].path_predicted


def test_a_rail_post_at_a_bends_entry_is_not_walked_into_the_path_by_the_yaw_step():
    """The ego drives straight, then enters a right bend: its yaw rate steps at once, but
    the radar's filtered lateral velocity of a post on the bend's outside still says
    what it said on the straight (0), so over ground the post seems to cross the path at
    w x. That step is the radar's lag, not motion: the post stays out of the path."""
    v, radius = 30 / 3.6, -50.0
    w = v / radius
    d = Drive()
    post_x, post_y = 16.0, 1.6     # beside the straight path (half-width 1.2 m)
    for _ in range(4):
        res = d.step(v, track(tid=4, x=post_x, y=post_y, vx=-v, vy=0.0))
        post_x -= v * 0.075
    for _ in range(3):       # the bend: the radar's vy still lags at 0
        res = d.step(v, track(tid=4, x=post_x, y=post_y, vx=-v, vy=0.0),
                     yaw_dps=math.degrees(w))
        post_x -= v * 0.075
        tgt = res.targets.targets[0]
        assert not tgt.path_predicted, tgt.reason
        assert res.command.decision is Decision.NONE, tgt.reason


def test_a_pedestrian_crossing_in_a_steady_bend_is_predicted_once_the_yaw_step_has_settled():
    """The allowance for a yaw step fades with the radar's lag (turn_lag_s): two seconds
    into a bend a pedestrian crossing at 1.5 m/s over ground is predicted as before."""
    v, radius = 20 / 3.6, 100.0
    w = v / radius
    d = Drive()
    d.step(v)
    for _ in range(27):      # about 2 s into the bend, nothing ahead
        d.step(v, yaw_dps=math.degrees(w))
    s, dist = 15.0, -3.0
    phi = s / radius
    rho = radius - dist
    x, y = rho * math.sin(phi), radius - rho * math.cos(phi)
    gvx, gvy = -1.5 * math.sin(phi), 1.5 * math.cos(phi)
    ped = track(tid=3, x=x, y=y, vx=gvx - v + w * y, vy=gvy - w * x)
    results = [d.step(v, ped, yaw_dps=math.degrees(w)) for _ in range(3)]
    tgt = results[-1].targets.targets[0]
    assert tgt.path_predicted and tgt.in_path


def test_unseen_turn_is_the_median_of_agreeing_stationary_drifts():
    assert unseen_turn([0.02, 0.019, 0.022, 0.115, 0.017], 3, 0.01) == pytest.approx(0.02)
    assert unseen_turn([-0.03, -0.028, -0.165], 3, 0.01) == pytest.approx(-0.03)
    assert unseen_turn([0.02, 0.02], 3, 0.01) == 0.0                 # too few
    assert unseen_turn([0.004, -0.003, 0.002, 0.006], 3, 0.01) == 0.0  # noise
    # The median turns, but only half of them do (the others measured no turn): none.
    assert unseen_turn([0.03, 0.03, 0.03, 0.0, 0.001, 0.002], 3, 0.01) == 0.0
    assert unseen_turn([0.03, 0.03, 0.03, 0.03, 0.001, 0.002], 3, 0.01) == pytest.approx(0.03)


# The deployed default: one cycle of sideways motion is motion.
ONE_CYCLE: dict[str, Any] = {"corridor": {"prediction": {"confirm_cycles": 1}}}


def _posts_entering_a_bend(d: Drive, v: float, w: float, y: float, seen: bool,
                           *extra: RadarTrack) -> CycleResult:
    """Four rail posts `y` beside a straight road, 12-30 m ahead, then a radar cycle in
    which the ego has begun to turn at `w` (the radar's velocities show it: vy = -w x)
    while the vehicle state still says straight, or already says it (`seen`)."""
    xs = [12.0, 18.0, 24.0, 30.0]
    for _ in range(4):
        d.step(v, *[track(tid=i + 1, x=x, y=y, vx=-v, vy=0.0) for i, x in enumerate(xs)])
        xs = [x - v * 0.075 for x in xs]
    posts = [track(tid=i + 1, x=x, y=y, vx=-v + w * y, vy=-w * x) for i, x in enumerate(xs)]
    return d.step(v, *posts, *extra, yaw_dps=math.degrees(w) if seen else 0.0)


def test_posts_drifting_with_a_turn_the_vehicle_state_has_not_shown_yet_still_stand():
    """The radar cycle already turned, the yaw rate was sampled before it: every post
    beside the path drifts across it at w x. They stood still the cycle before, all drift
    alike: the ego's turn, not motion. Off (unseen_turn_min_tracks 0), the nearest post
    is predicted across the path and braked for."""
    v, w = 40 / 3.6, 40 / 3.6 / 100.0          # a left bend of 100 m at 40 km/h
    res = _posts_entering_a_bend(Drive(**ONE_CYCLE), v, w, 1.6, seen=False)
    assert not any(t.path_predicted for t in res.targets.targets)
    assert res.command.decision is Decision.NONE
    assert "stationary returns turn +6.4 deg/s more" in res.targets.path
    off = _posts_entering_a_bend(Drive(**ONE_CYCLE, kinematic={"unseen_turn_min_tracks": 0}),
                                 v, w, 1.6, seen=False)
    assert any(t.path_predicted and t.in_path for t in off.targets.targets)
    assert off.command.decision is not Decision.NONE
    # The vehicle state shows the turn: nothing unseen, and no post moves over ground.
    seen = _posts_entering_a_bend(Drive(**ONE_CYCLE), v, w, 1.6, seen=True)
    assert "stationary returns" not in seen.targets.path
    assert not any(t.path_predicted for t in seen.targets.targets)


def test_an_unseen_turn_leaves_a_coasting_track_as_it_was_predicted():
    """A post the radar missed this cycle coasts on the velocity predicted before the
    turn (none sideways): the turn is not added to it, or it would walk into the path."""
    v, w = 40 / 3.6, 40 / 3.6 / 100.0
    coasting = msgspec.structs.replace(track(tid=9, x=20.0, y=-1.6, vx=-v, vy=0.0),
                                       misses=1)
    res = _posts_entering_a_bend(Drive(**ONE_CYCLE), v, w, 1.6, False, coasting)
    assert "stationary returns turn" in res.targets.path
    tgt = {t.track_id: t for t in res.targets.targets}[9]
    assert not tgt.path_predicted, tgt.reason
    assert res.command.decision is Decision.NONE, res.command.reason


def test_an_unseen_turn_leaves_a_track_that_was_already_moving_as_it_is():
    """A pedestrian crossing toward the path before the turn keeps its motion: only what
    stood still is excused."""
    v, w = 40 / 3.6, 40 / 3.6 / 100.0
    d = Drive(**ONE_CYCLE)
    xs, ped_y = [12.0, 18.0, 24.0, 30.0], -3.0
    for _ in range(4):
        ped = track(tid=9, x=22.0, y=ped_y, vx=-v, vy=1.5)
        d.step(v, ped, *[track(tid=i + 1, x=x, y=-6.0, vx=-v, vy=0.0)
                         for i, x in enumerate(xs)])
        xs = [x - v * 0.075 for x in xs]
        ped_y += 1.5 * 0.075
    posts = [track(tid=i + 1, x=x, y=-6.0, vx=-v, vy=-w * x) for i, x in enumerate(xs)]
    ped = track(tid=9, x=22.0, y=ped_y, vx=-v, vy=1.5 - w * 22.0)
    res = d.step(v, ped, *posts)
    assert "stationary returns turn" in res.targets.path
    tgt = {t.track_id: t for t in res.targets.targets}[9]
    assert tgt.path_predicted and tgt.in_path, tgt.reason


def test_one_track_setting_off_is_no_turn():
    """A cyclist waiting beside the path sets off across it while the posts stand: no
    turn to excuse it, it is predicted into the path."""
    v = 40 / 3.6
    d = Drive(**ONE_CYCLE)
    xs = [12.0, 18.0, 24.0, 30.0]
    for _ in range(4):
        d.step(v, track(tid=9, x=20.0, y=-2.5, vx=-v, vy=0.0),
               *[track(tid=i + 1, x=x, y=-6.0, vx=-v, vy=0.0) for i, x in enumerate(xs)])
        xs = [x - v * 0.075 for x in xs]
    res = d.step(v, track(tid=9, x=20.0, y=-2.5, vx=-v, vy=2.0),
                 *[track(tid=i + 1, x=x, y=-6.0, vx=-v, vy=0.0) for i, x in enumerate(xs)])
    assert "stationary returns" not in res.targets.path
    tgt = {t.track_id: t for t in res.targets.targets}[9]
    assert tgt.path_predicted and tgt.in_path, tgt.reason


def test_low_speed_no_new_activation_and_standstill_hold_then_release():
    d = Drive(kinematic={"standstill_hold_s": 0.3})
    v = 20 / 3.6
    res = d.step(v, ahead(8.0, v))
    assert res.command.decision is Decision.BRAKE
    # Stopped 1.5 m before the target: held at the standstill level, then released.
    res = d.step(0.0, ahead(1.5 + 3.0, 0.0))
    assert res.command.decision is Decision.BRAKE and res.command.held
    assert res.command.brake_level_pct == 50.0
    assert "standstill hold" in res.command.reason
    for _ in range(5):
        res = d.step(0.0, ahead(4.5, 0.0))
    assert res.command.decision is Decision.NONE
    # Moving off again re-arms the rule.
    res = d.step(v, ahead(8.0, v))
    assert res.command.decision is Decision.BRAKE


def test_level_never_drops_within_one_brake():
    v = 50 / 3.6
    d = Drive()
    assert d.step(v, ahead(25.0, v)).command.brake_level_pct == 100.0
    # A cycle that asks only for a lower stage (the brake is working) keeps 100 %.
    res = d.step(v * 0.7, ahead(24.0, v * 0.7))
    assert res.targets.targets[0].decision is Decision.WARNING
    assert res.command.decision is Decision.BRAKE
    assert res.command.brake_level_pct == 100.0


@pytest.mark.parametrize(("driver", "override"), [
    ({"kickdown": True}, "kick-down"),
    ({"accelerator_pedal_pct": 98.0}, "kick-down"),
    ({"steering_wheel_rate_dps": -250.0}, "steering"),
    ({"steering_wheel_angle_deg": 120.0}, "steering"),
    ({"brake_pedal_pressed": True}, "brake pedal"),
])
def test_driver_override_cancels_and_suppresses(driver, override):
    v = 40 / 3.6
    d = Drive()
    assert d.step(v, ahead(15.0, v)).command.decision is Decision.BRAKE
    res = d.step(v, ahead(14.0, v), **driver)
    cmd = res.command
    assert cmd.decision is Decision.WARNING and cmd.brake_level_pct == 0.0
    assert cmd.override == override and res.targets.override == override
    assert "driver override" in cmd.reason and "brake cancelled" in cmd.reason
    assert not cmd.held


def test_kickdown_suppresses_for_suppress_s_after_it_ends_the_brake_pedal_only_while_pressed():
    v = 40 / 3.6
    d = Drive(override={"suppress_s": 0.2})
    d.step(v, ahead(40.0, v), kickdown=True)
    res = d.step(v, ahead(15.0, v))                   # 75 ms after: still suppressed
    assert res.command.override == "kick-down"
    for _ in range(3):
        res = d.step(v, ahead(15.0, v))
    assert res.command.override == "" and res.command.decision is Decision.BRAKE
    d2 = Drive(override={"suppress_s": 5.0})
    d2.step(v, ahead(15.0, v), brake_pedal_pressed=True)
    assert d2.step(v, ahead(14.0, v)).command.decision is Decision.BRAKE


def test_a_bend_steering_angle_below_the_threshold_does_not_override():
    v = 40 / 3.6
    res = Drive().step(v, ahead(15.0, v), steering_wheel_angle_deg=46.0)
    assert res.command.decision is Decision.BRAKE and res.command.override == ""


def test_override_off_keeps_braking():
    v = 40 / 3.6
    res = Drive(override={"enabled": False}).step(v, ahead(15.0, v), kickdown=True)
    assert res.command.decision is Decision.BRAKE


# -- the degraded mode ------------------------------------------------------------------------


def test_missing_vehicle_state_is_at_most_warning_with_the_reason():
    d = Drive()
    res = d.cycle(ahead(8.0, 5.0))        # the paper's rule would brake: TTC_eff 0.6 s
    cmd = res.command
    assert cmd.decision is Decision.WARNING
    assert "vehicle/motion: nothing received" in cmd.reason
    assert "at most WARNING" in cmd.reason
    assert res.targets.vehicle_state.startswith("vehicle/motion: nothing received")
    assert res.targets.ego_speed_mps is None


def test_stale_motion_falls_back_after_the_bound_and_recovers():
    d = Drive()
    v = 20 / 3.6
    assert d.step(v, ahead(8.0, v)).command.decision is Decision.BRAKE
    d.core.hold.clear()
    d.t += 200 * MS                                  # nothing for 0.2 s > 0.1 s
    res = d.cycle(ahead(7.0, v))
    assert res.command.decision is Decision.WARNING
    assert "vehicle/motion: newest is" in res.targets.vehicle_state
    assert d.core.vehicle.motion.counts.get("went_stale") == 1
    assert d.step(v, ahead(6.0, v)).command.decision is Decision.BRAKE


def test_missing_driver_inputs_alone_is_at_most_warning_on_the_path():
    core = make_core(decision=KINEMATIC)
    header = Header(seq=0, source="t", stamp_ns=T0, pub_mono_ns=0)
    core.on_vehicle(EgoMotion(header=header, speed_mps=5.0, yaw_rate_dps=0.0), T0, 0)
    res = core.process(cycle(ahead(8.0, 5.0), stamp_ns=T0 + 10 * MS),
                       feed(frame(T0 + 10 * MS)), T0 + 15 * MS, 15 * MS)
    assert res.command.decision is Decision.WARNING
    assert "vehicle/driver: nothing received" in res.command.reason
    assert res.targets.ego_speed_mps == 5.0


def test_late_vehicle_samples_are_refused_and_counted():
    core = make_core(decision=KINEMATIC)
    old = Header(seq=0, source="t", stamp_ns=T0 - 500 * MS, pub_mono_ns=0)
    assert not core.on_vehicle(EgoMotion(header=old, speed_mps=5.0, yaw_rate_dps=0.0),
                               T0, 0)
    assert core.vehicle.motion.counts.get("late") == 1


def test_the_paper_rule_reads_no_vehicle_state():
    core = make_core()
    res = core.process(cycle(ahead(8.0, 5.0)), feed(frame()), T0 + 5 * MS, 1)
    assert res.command.decision is Decision.BRAKE and res.command.brake_level_pct == 100.0
    assert res.targets.vehicle_state == "" and res.targets.path == ""
    assert res.targets.targets[0].required_decel_mps2 is None
