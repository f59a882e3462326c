"""The consumer's vehicle state (common/vehicle_state.py): missing until a sample comes,
fresh for the registry's bound after each, stale after it with the reason and one
count per gap; late, out-of-order and future stamps handled and counted."""

import pytest

from aeb_radar_camera.common.keys import EGO_MOTION, VEHICLE_DRIVER
from aeb_radar_camera.common.messages import EgoMotion, Header
from aeb_radar_camera.common.vehicle_state import StateFreshness, StateInput, VehicleState

MS = 1_000_000
WALL = 1_700_000_000_000_000_000


def motion(stamp_ns: int, speed: float = 10.0) -> EgoMotion:
    return EgoMotion(Header(0, "vehicle/main", stamp_ns, 0), speed_mps=speed, yaw_rate_dps=0.0)


def test_the_bound_is_the_registrys():
    state = VehicleState()
    assert EGO_MOTION.max_age_s == VEHICLE_DRIVER.max_age_s == 0.1
    assert state.motion.max_age_ns == state.driver.max_age_ns == 100 * MS
    assert set(state.checks(0)) == {"vehicle/motion", "vehicle/driver"}


def test_missing_fresh_stale_and_fresh_again_counted_once_per_gap():
    inp: StateInput[EgoMotion] = StateInput.from_spec(EGO_MOTION)
    msg, check = inp.current(0)
    assert msg is None and check.freshness is StateFreshness.MISSING
    assert check.reason == "vehicle/motion: nothing received" and check.age_s is None
    first = motion(WALL)
    assert inp.observe(first, 0, WALL)
    assert inp.current(100 * MS) == (first, inp.check(100 * MS))   # fresh at the bound
    msg, check = inp.current(100 * MS + 1)
    assert msg is None and check.freshness is StateFreshness.STALE
    assert check.reason == "vehicle/motion: newest is 0.100 s old (bound 0.100 s)"
    inp.check(300 * MS)                       # the same gap: counted once
    assert inp.counts.get("went_stale") == 1
    assert inp.latest is first                # kept for display, never handed out stale
    second = motion(WALL + 400 * MS)
    inp.observe(second, 400 * MS, WALL + 400 * MS)
    assert inp.current(450 * MS)[0] is second
    inp.check(600 * MS)
    assert inp.counts.snapshot() == {"accepted": 2, "checked_missing": 1, "checked_stale": 3,
                                     "went_stale": 2}


def test_a_gap_no_check_saw_while_fresh_is_still_counted():
    inp: StateInput[EgoMotion] = StateInput.from_spec(EGO_MOTION)
    inp.observe(motion(WALL), 0, WALL)
    assert inp.check(1000 * MS).freshness is StateFreshness.STALE
    assert inp.counts.get("went_stale") == 1


def test_a_sample_measured_too_long_ago_is_not_taken():
    inp: StateInput[EgoMotion] = StateInput.from_spec(EGO_MOTION)
    assert not inp.observe(motion(WALL - 150 * MS), 0, WALL)        # 150 ms old on arrival
    check = inp.check(0)
    assert check.freshness is StateFreshness.MISSING
    assert check.reason == "vehicle/motion: nothing received, 1 late samples refused"
    assert inp.observe(motion(WALL - 50 * MS), 0, WALL)
    assert not inp.observe(motion(WALL - 60 * MS), 1, WALL)         # older than the newest
    assert inp.observe(motion(WALL + 500 * MS), 2, WALL)            # clocks disagree
    assert inp.counts.snapshot() == {"late": 1, "checked_missing": 1, "accepted": 2,
                                     "out_of_order": 1, "future_stamp": 1}


def test_without_the_stamp_check_only_the_arrival_counts():
    inp: StateInput[EgoMotion] = StateInput.from_spec(EGO_MOTION, stamp_check=False)
    assert inp.observe(motion(WALL - 10_000 * MS), 0, WALL)
    assert inp.check(50 * MS).fresh


def test_bounds_must_be_positive():
    with pytest.raises(ValueError, match="max_age_s"):
        StateInput("x", 0.0)
    with pytest.raises(ValueError, match="max_stamp_age_s"):
        StateInput("x", 0.1, 0.0)


def test_a_re_run_takes_each_input_as_the_recorded_decision_judged_it():
    state = VehicleState(stamp_check=False)
    state.motion.observe(motion(WALL), 0, WALL)
    # the recording's arrival times say fresh (50 ms); the live instance found it stale
    live = "vehicle/motion: newest is 0.130 s old (bound 0.100 s)"
    assert state.sample(50 * MS).motion is not None
    pinned = state.sample_as(f"{live}; vehicle/driver: nothing received", 50 * MS)
    assert pinned.motion is None and pinned.motion_check.freshness is StateFreshness.STALE
    assert pinned.driver_check.freshness is StateFreshness.MISSING
    assert pinned.reason == f"{live}; vehicle/driver: nothing received"
    # and the other way: stale by the recording's times, fresh live
    late = state.sample_as("vehicle/driver: nothing received", 300 * MS)
    assert late.motion is not None and late.motion_check.fresh
    assert late.reason == "vehicle/driver: nothing received"
    assert state.sample(300 * MS).motion is None
    # a verdict that names neither input holds for both
    unread = state.sample_as("vehicle state not read", 50 * MS)
    assert unread.motion is None and unread.driver is None
    assert "vehicle state not read" in unread.motion_check.reason
