"""Path prediction in the in-path decision: a target moving sideways is in the path iff it
is in the corridor when the ego's front reaches it; every branch, on the pure core.

Defaults: corridor 0.9 + 0.3 = 1.2 m either side; prediction horizon 4 s, lateral speed
>= 0.5 m/s for 2 consecutive cycles, arrival margin 0.3 s.
"""

import math
import random

import msgspec
import pytest

from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import ConfigError, load_config
from aeb_radar_camera.common.messages import Decision, RadarTrack, Verification
from aeb_radar_camera.services.fusion.decision import (
    LateralMotion,
    corridor_window,
    crossing_window,
)
from aeb_radar_camera.services.fusion.verifiers import GateResult
from tests.fusion.helpers import (
    MS,
    T0,
    FixedVerifier,
    cycle,
    feed,
    frame,
    make_core,
    most_severe,
    run,
    track,
)

CYCLE_NS = 75 * MS


def cycles(core, *steps: tuple[RadarTrack, ...]):
    """Consecutive radar cycles (75 ms apart), each with a fresh frame; the results."""
    return [run(core, *tracks, stamp_ns=T0 + i * CYCLE_NS, seq=i)
            for i, tracks in enumerate(steps)]


def moved(t: RadarTrack, dt: float) -> RadarTrack:
    """The same track dt seconds later, at constant velocity."""
    return msgspec.structs.replace(
        track(tid=t.track_id, x=t.x_m + t.vx_mps * dt, y=t.y_m + t.vy_mps * dt,
              vx=t.vx_mps, vy=t.vy_mps), obj_class=t.obj_class)


def only(result):
    assert len(result.targets.targets) == 1
    return result.targets.targets[0]


def test_a_target_crossing_into_the_path_brakes_with_the_time_to_reach_the_front():
    # 10 m ahead, 4 m left, closing at 5 m/s along x: the front reaches it in 2.0 s;
    # walking right at 1.5 m/s it is in the corridor from 1.87 s to 3.47 s.
    first = track(tid=3, x=10.0, y=4.0, vx=-5.0, vy=-1.5)
    core = make_core()
    before, after = cycles(core, (first,), (moved(first, 0.075),))
    # One cycle of sideways motion is not yet confirmed: judged on its offset, out.
    assert only(before).decision is Decision.NONE and "out of corridor" in only(before).reason
    assert not only(before).path_predicted
    tgt = only(after)
    assert tgt.in_path and tgt.path_predicted and tgt.verification is Verification.VERIFIED
    x = 10.0 - 5.0 * 0.075
    assert tgt.ttc_s == pytest.approx(x / 5.0)          # not r / |range rate| (about 2.0 s)
    assert tgt.ttc_s != pytest.approx(tgt.range_m / -tgt.range_rate_mps, abs=0.02)
    assert tgt.decision is Decision.BRAKE and after.command.decision is Decision.BRAKE
    assert after.command.ttc_s == pytest.approx(x / 5.0)
    assert "in path by prediction" in tgt.reason and "ego arrives in 1.93 s" in tgt.reason


def test_without_prediction_the_same_crossing_target_is_out_of_the_corridor():
    first = track(tid=3, x=10.0, y=4.0, vx=-5.0, vy=-1.5)
    core = make_core(decision={"corridor": {"prediction": {"enabled": False}}})
    _, after = cycles(core, (first,), (moved(first, 0.075),))
    assert only(after).decision is Decision.NONE and not only(after).path_predicted
    assert "out of corridor" in only(after).reason


@pytest.mark.parametrize(("y", "vy", "why"), [
    (0.5, -2.0, "inside now, gone 0.85 s from now"),
    (3.0, -4.0, "crosses from 0.45 s to 1.05 s"),
])
def test_a_target_that_leaves_the_corridor_before_the_ego_arrives_does_not_trigger(y, vy, why):
    # The front reaches x = 15 m in 3.0 s, well after the target has gone.
    first = track(tid=1, x=15.0, y=y, vx=-5.0, vy=vy)
    core = make_core(decision={"corridor": {"prediction": {"confirm_cycles": 1}}})
    tgt = only(cycles(core, (first,))[0])
    assert tgt.path_predicted and not tgt.in_path, why
    assert tgt.decision is Decision.NONE and "out of corridor" in tgt.reason
    assert "ego arrives in 3.00 s" in tgt.reason


def test_a_target_leaving_just_within_the_arrival_margin_is_still_in_the_path():
    # Leaves at (0.5 + 1.2) / 2 = 0.85 s; the front arrives at 1.1 s: within 0.3 s.
    near = track(tid=1, x=5.5, y=0.5, vx=-5.0, vy=-2.0)
    core = make_core(decision={"corridor": {"prediction": {"confirm_cycles": 1}}})
    tgt = only(cycles(core, (near,))[0])
    assert tgt.in_path and tgt.decision is Decision.BRAKE
    # With no margin the same target is out.
    strict = make_core(decision={"corridor": {"prediction": {"confirm_cycles": 1,
                                                             "arrival_margin_s": 0.0}}})
    assert only(cycles(strict, (near,))[0]).decision is Decision.NONE


def test_a_pedestrian_walking_beside_the_path_parallel_stays_out():
    # 2.2 m right of the centre line, walking forward at 1.3 m/s, the ego at 5.5 m/s.
    walker = track(tid=5, x=12.0, y=-2.2, vx=-4.2, vy=0.03)
    steps = [(moved(walker, i * 0.075),) for i in range(6)]
    results = cycles(make_core(), *steps)
    for res in results:
        tgt = only(res)
        assert not tgt.in_path and not tgt.path_predicted
        assert tgt.decision is Decision.NONE and res.command.decision is Decision.NONE


def test_a_stationary_box_beside_the_lane_with_noisy_lateral_velocity_stays_out():
    # 1.9 m left, passed at 10 km/h; the radar's lateral velocity jitters around zero,
    # with one spike above the minimum speed and one flip of direction above it.
    noise = [0.3, -0.4, 0.6, -0.2, 0.45, 0.7, -0.7, 0.1]
    steps = [(track(tid=2, x=9.0 - 0.21 * i, y=1.9, vx=-2.78, vy=-vy),)
             for i, vy in enumerate(noise)]
    for res in cycles(make_core(), *steps):
        tgt = only(res)
        assert not tgt.in_path and tgt.decision is Decision.NONE, tgt.reason
    # The guards are what keeps it out: with no minimum speed and no confirmation the
    # first noisy cycle (0.3 m/s towards the lane, the ego 3.2 s away) walks it in.
    naive = make_core(decision={"corridor": {"prediction": {
        "min_lateral_speed_mps": 0.0, "confirm_cycles": 1}}})
    assert only(cycles(naive, *steps[:1])[0]).in_path


def test_a_receding_target_moving_sideways_is_never_predicted_into_the_path():
    first = track(tid=4, x=10.0, y=3.0, vx=1.0, vy=-2.0)
    _, after = cycles(make_core(), (first,), (moved(first, 0.075),))
    tgt = only(after)
    assert not tgt.path_predicted and tgt.decision is Decision.NONE
    assert "not closing" in tgt.reason


def test_a_target_reached_later_than_the_horizon_is_judged_on_its_offset():
    # The front reaches x = 24 m in 4.8 s (horizon 4 s + 0.3 s margin): no prediction.
    far = track(tid=6, x=24.0, y=0.5, vx=-5.0, vy=-2.0)
    core = make_core(decision={"warning_ttc_eff_s": 5.0,
                               "corridor": {"prediction": {"confirm_cycles": 1}}})
    tgt = only(cycles(core, (far,))[0])
    assert not tgt.path_predicted and tgt.in_path and tgt.decision is Decision.WARNING


def test_a_held_brake_reports_the_predicted_targets_time_to_reach_the_front():
    core = make_core(decision={"hold_s": 1.0, "corridor": {"prediction": {"confirm_cycles": 1}}})
    crossing = track(tid=8, x=8.0, y=2.0, vx=-5.0, vy=-1.5)
    first = cycles(core, (crossing,))[0]
    assert first.command.decision is Decision.BRAKE
    # Next cycle the camera rejects it; the brake is held, with the track's arrival time.
    core.verifier = FixedVerifier(verdict=False)
    later = moved(crossing, 0.075)
    res = run(core, later, stamp_ns=T0 + CYCLE_NS, seq=1)
    assert res.command.held and res.command.track_id == 8
    assert res.command.ttc_s == pytest.approx(later.x_m / 5.0)


def test_the_early_command_equals_the_most_severe_of_all_targets_with_prediction():
    rng = random.Random(11)

    class Coin(FixedVerifier):
        def verify(self, obs):
            return GateResult(0.1, rng.random() < 0.6)

    core = make_core(Coin(), decision={"hold_s": 0.0,
                                       "corridor": {"prediction": {"confirm_cycles": 1}}})
    predicted = 0
    for n in range(80):
        tracks = [track(tid=i, x=rng.uniform(2.0, 27.0), y=rng.uniform(-5.0, 5.0),
                        vx=rng.uniform(-12.0, 3.0), vy=rng.uniform(-3.0, 3.0))
                  for i in range(rng.randint(0, 8))]
        res = core.process(cycle(*tracks, seq=n), feed(frame()), T0 + MS, 1)
        predicted += sum(t.path_predicted and t.decision is not Decision.NONE
                         for t in res.targets.targets)
        assert (res.command.decision, res.command.track_id) == most_severe(
            res.targets.targets)
    assert predicted > 10        # the random cycles did exercise the prediction


@pytest.mark.parametrize(("lateral", "speed", "expected"), [
    (3.0, -2.0, (0.9, 2.1)),                  # from the left, moving right
    (-3.0, 2.0, (0.9, 2.1)),                  # from the right, moving left
    (0.0, 1.0, (-1.2, 1.2)),                  # inside now: entered 1.2 s ago
    (3.0, 2.0, (-2.1, -0.9)),                 # moving away: it was inside in the past
    (0.5, 0.0, (-math.inf, math.inf)),        # standing inside
    (2.0, 0.0, (math.inf, math.inf)),         # standing outside: never
])
def test_corridor_window(lateral, speed, expected):
    assert corridor_window(lateral, speed, 1.2) == pytest.approx(expected)


@pytest.mark.parametrize(("lateral", "speed", "trailing", "expected"), [
    (3.0, -2.0, 0.0, (0.9, 2.1)),             # a point: corridor_window's
    (3.0, -2.0, 4.8, (0.9, 4.5)),             # its end 4.8 m behind, at 7.8 m, leaves last
    (-3.0, 2.0, 1.0, (0.9, 2.6)),             # from the right: its end at -4.0 m
    (0.5, 0.0, 4.8, (-math.inf, math.inf)),   # no sideways motion: no direction to trail
])
def test_crossing_window_holds_the_path_until_the_trailing_end_has_left(
        lateral, speed, trailing, expected):
    assert crossing_window(lateral, speed, 1.2, trailing) == pytest.approx(expected)


def crossing_car(y: float, obj_class: int = 1) -> RadarTrack:
    """A car (the radar's class 1) 10 m ahead crossing from the left at 15 km/h, the ego
    at 5 m/s."""
    return msgspec.structs.replace(track(tid=4, x=10.0, y=y, vx=-5.0, vy=-15 / 3.6),
                                   obj_class=obj_class)


def test_a_crossing_car_whose_front_has_left_the_path_is_in_it_until_its_length_has():
    # Its radar point (the front) is in the corridor 0.2-0.8 s from now, the ego arrives
    # in 1.9 s: the point alone is out; 4.8 m of car behind it leave the corridor 1.9 s
    # from now.
    trailing = {"corridor": {"prediction": {"trailing_m": {"car": 4.8, "truck": 12.0}}}}
    first = crossing_car(2.0)
    for decision, expected in (({}, Decision.NONE), (trailing, Decision.BRAKE)):
        _, after = cycles(make_core(decision=decision), (first,), (moved(first, 0.075),))
        assert only(after).decision is expected, only(after).reason
        assert only(after).path_predicted
    # A class without a length (or none: clusters) is a point.
    for cls in (3, 0, -1):
        other = crossing_car(2.0, cls)
        _, after = cycles(make_core(decision=trailing), (other,), (moved(other, 0.075),))
        assert only(after).decision is Decision.NONE


def test_trailing_lengths_name_the_radars_classes():
    with pytest.raises(ConfigError, match="unknown object class lorry"):
        make_core(decision={"corridor": {"prediction": {"trailing_m": {"lorry": 12.0}}}})


def test_lateral_motion_needs_consecutive_cycles_in_one_direction_and_forgets_gone_tracks():
    motion = LateralMotion(min_speed_mps=0.5, cycles=3)
    seen = [motion.update([track(tid=1, vy=vy)]) for vy in (0.6, 0.7, -0.8, -0.6, -0.9, 0.2)]
    assert seen == [set(), set(), set(), set(), {1}, set()]
    motion.update([track(tid=2, vy=1.0)])
    motion.update([track(tid=2, vy=1.0)])
    motion.update([])                          # track 2 missing for a cycle: start again
    assert motion.update([track(tid=2, vy=1.0)]) == set()


def test_paper_profile_has_no_path_prediction_and_the_default_has_it():
    paper = load_config("deploy/fusion-paper.toml", FusionConfig).fusion.decision.corridor
    shipped = load_config("deploy/fusion.toml", FusionConfig).fusion.decision.corridor
    assert not paper.prediction.enabled
    assert shipped.prediction.enabled and shipped.enabled
