"""The tracker's vectorised pieces against plain reference computations: the greedy
assignment, the gate's candidate search (dense and strip grid), and the Kalman update in
its R S^-1 form against the textbook 4x4 equations."""

import numpy as np
import pytest

from common.config.radar import TrackerSettings
from services.radar.detections import Detections
from services.radar.neighbours import candidates_in_boxes, pairs_within, pairs_within_self
from services.radar.tracker import KalmanTracker, greedy_pairs


def plain_greedy(ti, di, cost):
    taken_t, taken_d, out = set(), set(), set()
    for _cost, t, d in sorted(zip(cost.tolist(), ti.tolist(), di.tolist(), strict=True)):
        if t not in taken_t and d not in taken_d:
            taken_t.add(t)
            taken_d.add(d)
            out.add((t, d))
    return out


@pytest.mark.parametrize("seed", range(20))
def test_greedy_pairs_is_the_sequential_greedy_ties_included(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 300))
    ti = rng.integers(0, 40, n)
    di = rng.integers(0, 40, n)
    pairs = np.unique(np.stack([ti, di]), axis=1)           # each pair once
    ti, di = pairs[0], pairs[1]
    cost = rng.integers(0, 8, len(ti)).astype(float)        # many exact ties
    mt, md = greedy_pairs(ti, di, cost)
    got = set(zip(mt.tolist(), md.tolist(), strict=True))
    assert got == plain_greedy(ti, di, cost) and len(got) == len(mt)


@pytest.mark.parametrize("seed", range(10))
def test_candidates_cover_every_pair_in_the_boxes(seed):
    rng = np.random.default_rng(seed)
    n, m = int(rng.integers(1, 300)), int(rng.integers(1, 300))
    # Positions on a 0.2 m grid, as the radar quantises them: many pairs exactly on a
    # box edge.
    def grid(lo, hi, k):
        return np.round(rng.uniform(lo, hi, k) / 0.2) * 0.2

    ax, ay, bx, by = grid(-5, 60, n), grid(-20, 20, n), grid(-5, 60, m), grid(-20, 20, m)
    half_x = 1.6
    half_y = np.round(rng.uniform(0.2, 3.0, n) / 0.2) * 0.2
    i, j = candidates_in_boxes(ax, ay, half_x, half_y, bx, by)
    got = set(zip(i.tolist(), j.tolist(), strict=True))
    inside = (np.abs(ax[:, None] - bx[None, :]) <= half_x) & \
        (np.abs(ay[:, None] - by[None, :]) <= half_y[:, None])
    assert {(int(a), int(b)) for a, b in zip(*np.nonzero(inside), strict=True)} <= got
    assert len(got) == len(i)                                # no pair twice


@pytest.mark.parametrize("radius", [1.4, 3.0])
def test_pair_searches_keep_pairs_exactly_on_the_radius(radius):
    # Points on a 0.2 m grid (positions as the radar quantises them): for these radii
    # one pair lies exactly on the radius, where a window bound x + r rounds below the
    # other point although the distance test keeps it.
    x = np.arange(200, dtype=np.float64) * 0.2
    y = np.zeros(200)
    dx = x[:, None] - x[None, :]
    near = dx * dx <= radius * radius          # the searches' own distance test
    expect = {(a, b) for a, b in zip(*np.nonzero(near), strict=True) if a < b}
    i, j = pairs_within_self(x, y, radius)
    assert {(min(a, b), max(a, b)) for a, b in zip(i.tolist(), j.tolist(), strict=True)} == expect
    i, j = pairs_within(x, y, x.copy(), y.copy(), radius)
    assert len(i) == 2 * len(expect) + len(x)


def tracker_with_tracks(rng, n: int) -> KalmanTracker:
    tracker = KalmanTracker(TrackerSettings())
    det = Detections.of(x=rng.uniform(2, 20, n), y=rng.uniform(-10, 10, n),
                        vx=rng.uniform(-12, 3, n), vy=rng.uniform(-1, 1, n))
    for k in range(3):
        tracker.step(det, k * 0.075)
        det = Detections(det.floats + rng.normal(0, 0.1, det.floats.shape), det.ints)
    tracker.predict(0.075)
    return tracker


def test_dense_and_strip_grid_gates_find_the_same_pairs():
    rng = np.random.default_rng(11)
    tracker = tracker_with_tracks(rng, 120)
    det = Detections.of(x=rng.uniform(2, 20, 150), y=rng.uniform(-10, 10, 150),
                        vx=rng.uniform(-12, 3, 150), vy=rng.uniform(-1, 1, 150))
    half = tracker._innovation()
    dense = tracker._gated_dense(det)
    sparse = tracker._gated_sparse(det, half)
    as_set = [dict(zip(zip(t.tolist(), d.tolist(), strict=True), c.tolist(), strict=True))
              for t, d, c in (dense, sparse)]
    assert len(as_set[0]) > 50 and as_set[0].keys() == as_set[1].keys()
    for key, cost in as_set[0].items():
        assert as_set[1][key] == pytest.approx(cost, rel=1e-12)


def test_update_equals_the_textbook_kalman_update():
    rng = np.random.default_rng(5)
    tracker = tracker_with_tracks(rng, 30)
    s = tracker.s
    st = tracker.state.copy()
    det = Detections(st[0:5] + rng.normal(0, 0.3, (5, 30)), np.zeros((5, 30), dtype=np.int64))
    rows = np.arange(30)
    tracker._innovation()
    tracker._update(rows, det, rows)
    r = np.diag([s.pos_x_std_m**2, s.vel_x_std_mps**2, s.pos_y_std_m**2, s.vel_y_std_mps**2])
    for k in range(30):
        # [x, vx, y, vy] with the full 4x4 covariance from the per-axis blocks.
        p = np.zeros((4, 4))
        for axis in range(2):
            a = 2 * axis
            p[a, a], p[a, a + 1], p[a + 1, a], p[a + 1, a + 1] = (
                st[4 + axis, k], st[6 + axis, k], st[6 + axis, k], st[8 + axis, k])
        x = st[[0, 2, 1, 3], k]
        z = det.floats[[0, 2, 1, 3], k]
        gain = p @ np.linalg.inv(p + r)
        x_new = x + gain @ (z - x)
        p_new = (np.eye(4) - gain) @ p
        got = tracker.state[:, k]
        assert got[[0, 2, 1, 3]] == pytest.approx(x_new, rel=1e-9, abs=1e-12)
        for axis in range(2):
            a = 2 * axis
            assert [got[4 + axis], got[6 + axis], got[8 + axis]] == pytest.approx(
                [p_new[a, a], p_new[a, a + 1], p_new[a + 1, a + 1]], rel=1e-9, abs=1e-15)
