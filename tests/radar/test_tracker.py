"""The tracker on synthetic scenes with measurement noise, through the whole pipeline
(encoded ARS408 frames -> assembly -> decode -> prefilter -> merge -> Kalman tracker)."""

import msgspec
import numpy as np
import pytest

from aeb_radar_camera.common.config.radar import (
    CycleSettings,
    Expect,
    RadarSettings,
    TrackerSettings,
)
from aeb_radar_camera.common.messages import Header
from aeb_radar_camera.common.messages.radar import BusState
from aeb_radar_camera.services.radar.ars408 import (
    ClusterGeneral,
    ObjectGeneral,
    cluster_cycle_frames,
)
from aeb_radar_camera.services.radar.ars408.codec import encode
from aeb_radar_camera.services.radar.ars408.records import ObjectListStatus
from aeb_radar_camera.services.radar.core import RadarCore
from aeb_radar_camera.services.radar.detections import Detections
from aeb_radar_camera.services.radar.tracker import KalmanTracker
from tests.can_support import feed

DT = 0.075
# The scenes send general frames only; saying so lets every cycle out at its last frame.
NO_EXTRAS = CycleSettings(expect_quality=Expect.NO, expect_extended=Expect.NO)


def settings(**kw):
    return RadarSettings(cycle=NO_EXTRAS, **kw)


def q(v, step):
    return round(v / step) * step


def cluster(i, x, y, vx=0.0, vy=0.0, rcs=10.0):
    return ClusterGeneral(i, q(x, 0.2), q(y, 0.2), q(vx, 0.25), q(vy, 0.25), 0, q(rcs, 0.5))


def run_core(cycles, s=None, t0=100.0):
    """Each cycle a list of (x, y, vx, vy) in cluster mode; returns the core and the
    published tracks per cycle."""
    s = s or settings()
    core = RadarCore(s.sensors[0], s)
    out = []
    for k, dets in enumerate(cycles):
        frames = cluster_cycle_frames([cluster(i, *d) for i, d in enumerate(dets)], k)
        results = feed(core, [(f, t0 + k * DT) for f in frames])
        assert len(results) == 1 and results[0].complete
        out.append(results[0].tracks)
    return core, out


def run(cycles, s=None, t0=100.0):
    return run_core(cycles, s, t0)[1]


def confirmed(tracks):
    return [t for t in tracks if t.confirmed]


def test_single_cycle_ghosts_are_never_confirmed():
    rng = np.random.default_rng(3)
    cycles = []
    for _ in range(40):
        target = (12.0 + rng.normal(0, 0.1), rng.normal(0, 0.1), 0.0, 0.0)
        # Five ghosts per cycle, each somewhere else in the window, each seen once.
        ghosts = [(rng.uniform(3, 24), rng.uniform(-8, 8), rng.uniform(-10, 5), 0.0)
                  for _ in range(5)]
        ghosts = [g for g in ghosts if np.hypot(g[0] - 12.0, g[1]) > 4]
        cycles.append([target, *ghosts])
    published = run(cycles)
    for k, tracks in enumerate(published):
        assert len(tracks) >= 1
        conf = confirmed(tracks)
        if k >= 2:
            assert len(conf) == 1, f"cycle {k}: {conf}"
            assert conf[0].x_m == pytest.approx(12.0, abs=0.5)
        # Ghost tracks exist (tentative, published) but never confirm.
        assert all(abs(t.x_m - 12.0) < 1.0 for t in conf)
    assert sum(len(t) for t in published) > 3 * 40   # the ghosts were tracked, tentatively


def test_real_target_confirmed_on_its_third_update():
    rng = np.random.default_rng(4)
    cycles = [[(15.0 - 5.0 * DT * k + rng.normal(0, 0.1), rng.normal(0, 0.1), -5.0, 0.0)]
              for k in range(6)]
    published = run(cycles)
    states = [(t[0].hits, t[0].confirmed) for t in published]
    assert states[:4] == [(1, False), (2, False), (3, True), (4, True)]
    track = published[5][0]
    assert track.range_rate_mps == pytest.approx(-5.0, abs=0.3)   # closing is negative
    assert track.range_m == pytest.approx(15.0 - 5 * 5 * DT, abs=0.3)


def test_crossing_target_kept_through_one_missed_detection():
    rng = np.random.default_rng(5)
    cycles = []
    for k in range(20):
        y = 4.0 - 3.0 * DT * k
        det = [(10.0 + rng.normal(0, 0.1), y + rng.normal(0, 0.1), 0.0, -3.0)]
        cycles.append([] if k == 10 else det)
    published = run(cycles)
    before = confirmed(published[9])[0]
    coasting = published[10]
    assert len(coasting) == 1 and coasting[0].track_id == before.track_id
    assert coasting[0].misses == 1 and coasting[0].confirmed
    assert coasting[0].y_m == pytest.approx(4.0 - 3.0 * DT * 10, abs=0.3)   # predicted
    after = published[11]
    assert [t.track_id for t in after] == [before.track_id]
    assert after[0].confirmed and after[0].misses == 0
    assert published[19][0].track_id == before.track_id


def setting_off(k_start: int = 8, cycles: int = 12):
    """A cyclist waiting 3.8 m beside the path (closing at the ego's 8 m/s) who sets off
    across it at 4.2 m/s at cycle `k_start`: the first detection of the new motion lies
    where the track is, with a velocity the 4-d gate refuses."""
    out = []
    y = -3.8
    for k in range(cycles):
        vy = 4.2 if k >= k_start else 0.0
        if k > k_start:
            y += vy * DT
        out.append([(20.0 - 8.0 * DT * k, y, -8.0, vy)])
    return out


def test_a_target_that_sets_off_keeps_its_track_and_takes_its_new_velocity():
    published = run(setting_off())
    before = confirmed(published[7])
    assert len(before) == 1
    [now] = confirmed(published[8])
    assert now.track_id == before[0].track_id and now.misses == 0 and now.hits == 9
    assert now.vy_mps == pytest.approx(4.2, abs=0.3)       # measured, not filtered away
    assert [t.track_id for t in published[11]] == [before[0].track_id]


def test_the_radar_status_counts_the_re_acquired_tracks():
    for reacquire, expected in ((TrackerSettings().reacquire_chi2, 1), (0.0, 0)):
        core, _ = run_core(setting_off(), settings(tracker=TrackerSettings(
            reacquire_chi2=reacquire)))
        status = core.status(Header(0, "radar", 0, 0), BusState.ACTIVE,
                             0, "replay", "", 0.0, 0, {}, 0)
        assert status.tracks_resumed == expected


def test_re_acquisition_off_far_away_or_far_off_in_velocity_starts_a_new_track():
    off = run(setting_off(), settings(tracker=TrackerSettings(reacquire_chi2=0.0)))
    first = confirmed(off[7])[0].track_id
    assert [t.track_id for t in confirmed(off[8])] == [first]     # coasting, not updated
    assert confirmed(off[8])[0].misses == 1
    assert any(t.track_id != first and not t.confirmed for t in off[8])
    # A detection 2.5 m away (beyond the position gate, inside the distance cap) is
    # another object.
    cycles = [[(15.0, 0.0, 0.0, 0.0)]] * 6 + [[(15.0, 2.5, 0.0, 3.0)]]
    published = run(cycles)
    old = confirmed(published[5])[0].track_id
    assert {(t.track_id == old, t.misses) for t in published[6]} == {(True, 1), (False, 0)}
    # Where the track is, but 12 m/s off its velocity: a post beside a car ahead whose
    # own return was missed, not the car stopping dead.
    cycles = [[(15.0 + 1.5 * DT * k, 0.0, 1.5, 0.0)] for k in range(6)]
    cycles.append([(15.0 + 1.5 * DT * 6, 0.8, -10.5, 0.0)])
    published = run(cycles)
    old = confirmed(published[5])[0].track_id
    assert {(t.track_id == old, t.misses) for t in published[6]} == {(True, 1), (False, 0)}


def test_track_deleted_after_the_configured_misses():
    cycles = [[(10.0, 0.0, 0.0, 0.0)]] * 5 + [[]] * 4
    s = settings(tracker=TrackerSettings(delete_after_misses=3))
    published = run(cycles, s)
    assert [len(t) for t in published[5:]] == [1, 1, 0, 0]


def test_two_close_targets_with_different_velocities_stay_two_tracks():
    rng = np.random.default_rng(6)
    cycles = []
    for k in range(6):
        a = (15.0 - 2.0 * DT * k + rng.normal(0, 0.05), 0.0, -2.0, 0.0)
        b = (15.6 - 5.0 * DT * k + rng.normal(0, 0.05), 0.3, -5.0, 0.0)
        cycles.append([a, b])
    conf = confirmed(run(cycles)[5])
    assert len(conf) == 2
    rates = sorted(t.range_rate_mps for t in conf)
    assert rates == [pytest.approx(-5.0, abs=0.4), pytest.approx(-2.0, abs=0.4)]


def test_several_returns_from_one_object_merge_into_one_track():
    rng = np.random.default_rng(7)
    cycles = []
    for k in range(10):
        x = 12.0 - 4.0 * DT * k
        returns = [(x + rng.uniform(-0.6, 0.6), rng.uniform(-0.7, 0.7),
                    -4.0 + rng.normal(0, 0.1), 0.0) for _ in range(4)]
        cycles.append(returns)
    published = run(cycles)
    for tracks in published:
        assert len(tracks) == 1
    track = published[-1][0]
    assert track.confirmed and track.range_rate_mps == pytest.approx(-4.0, abs=0.3)


def test_radar_ids_help_but_are_not_trusted_when_they_swap():
    s = settings()
    core = RadarCore(s.sensors[0], s)
    a_id, b_id = 1, 2
    history = []
    for k in range(12):
        if k == 6:
            a_id, b_id = b_id, a_id          # the radar swaps its IDs
        objs = [ObjectGeneral(a_id, 10.0, 2.0, 0.0, 0.0, 1, 10.0),
                ObjectGeneral(b_id, 20.0, -2.0, 0.0, 0.0, 1, 10.0)]
        frames = [encode(ObjectListStatus(2, k, 1))] + [encode(o) for o in objs]
        [result] = feed(core, [(f, 50.0 + k * DT) for f in frames])
        history.append({round(t.x_m): t.track_id for t in result.tracks})
    assert history[5] == history[11]         # tracks stay with the positions


def test_receding_tracks_are_dropped_only_when_the_gate_is_on():
    cycles = [[(10.0 + 4.0 * DT * k, 0.0, 4.0, 0.0), (12.0, 3.0, 0.0, 0.0)] for k in range(5)]
    assert len(confirmed(run(cycles)[4])) == 2
    gated = settings(tracker=TrackerSettings(drop_receding=True))
    [kept] = confirmed(run(cycles, gated)[4])
    assert kept.x_m == pytest.approx(12.0, abs=0.2)


def test_a_gap_or_time_going_back_restarts_the_tracker():
    tracker = KalmanTracker(TrackerSettings())
    det = Detections.of(x=[10.0], y=[0.0])
    for k in range(4):
        tracker.step(det, 1.0 + k * DT)
    assert tracker.confirmed.tolist() == [True]
    tracker.step(det, 5.0)                   # 4.7 s gap: older than max_gap_s
    assert tracker.resets == 1 and tracker.confirmed.tolist() == [False]
    tracker.step(det, 5.0 + DT)
    tracker.step(det, 1.0)                   # backwards (a replay loop)
    assert tracker.resets == 2 and len(tracker) == 1


def test_covariance_shrinks_with_updates_and_grows_while_coasting():
    tracker = KalmanTracker(TrackerSettings())
    det = Detections.of(x=[10.0], y=[1.0])
    variances = []
    for k in range(5):
        tracker.step(det, k * DT)
        variances.append(tracker.tracks()[0].x_var_m2)
    assert variances[-1] < variances[0]
    tracker.step(Detections.empty(), 5 * DT)
    assert tracker.tracks()[0].x_var_m2 > variances[-1]


def test_tracks_are_valid_messages():
    [tracks] = run([[(10.0, -1.0, -3.0, 0.5)]])[-1:]
    msg = tracks[0]
    again = msgspec.msgpack.decode(msgspec.msgpack.encode(msg), type=type(msg))
    assert again == msg and msg.radar_object_id == 0


def test_an_empty_road_leaves_the_tracker_as_it_was_but_the_clock():
    tracker = KalmanTracker(TrackerSettings())
    state, meta = tracker.state, tracker.meta
    for k in range(3):
        tracker.step(Detections.empty(), 100.0 + k * DT)
    assert tracker.state is state and tracker.meta is meta and len(tracker) == 0
    assert tracker.last_t == 100.0 + 2 * DT
