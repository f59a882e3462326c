"""The tracker against plain reference computations: the greedy assignment, the gate's
candidate search, the Kalman update in its R S^-1 form against the textbook 4x4
equations, and whole runs against a textbook tracker written track by track, with few
tracks (every pair tested) and many (candidates from the strip grid)."""

import numpy as np
import pytest

from aeb_radar_camera.common.config.radar import TrackerSettings
from aeb_radar_camera.services.radar.detections import Detections
from aeb_radar_camera.services.radar.neighbours import candidates_in_boxes, pairs_within_self
from aeb_radar_camera.services.radar.tracker import (
    COV_PV,
    VAR_P,
    VAR_V,
    KalmanTracker,
    greedy_pairs,
)


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
def test_the_pair_search_keeps_pairs_exactly_on_the_radius(radius):
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


def tracker_with_tracks(rng, n: int) -> KalmanTracker:
    tracker = KalmanTracker(TrackerSettings())
    det = Detections.of(x=rng.uniform(2, 20, n), y=rng.uniform(-10, 10, n),
                        vx=rng.uniform(-12, 3, n), vy=rng.uniform(-1, 1, n))
    for k in range(3):
        tracker.step(det, k * 0.075)
        det = Detections(det.floats + rng.normal(0, 0.1, det.floats.shape), det.ints)
    tracker.predict(0.075)
    return tracker


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
            var_p, cov_pv, var_v = (st[row.start + axis, k] for row in (VAR_P, COV_PV, VAR_V))
            p[a, a], p[a, a + 1], p[a + 1, a], p[a + 1, a + 1] = var_p, cov_pv, cov_pv, var_v
        x = st[[0, 2, 1, 3], k]
        z = det.floats[[0, 2, 1, 3], k]
        gain = p @ np.linalg.inv(p + r)
        x_new = x + gain @ (z - x)
        p_new = (np.eye(4) - gain) @ p
        got = tracker.state[:, k]
        assert got[[0, 2, 1, 3]] == pytest.approx(x_new, rel=1e-9, abs=1e-12)
        for axis in range(2):
            a = 2 * axis
            assert [got[row.start + axis] for row in (VAR_P, COV_PV, VAR_V)] == pytest.approx(
                [p_new[a, a], p_new[a, a + 1], p_new[a + 1, a + 1]], rel=1e-9, abs=1e-15)


def _claim(pairs, used_t, used_d):
    """(track, detection) of `pairs` ((cost, track, detection)), cheapest first, each track
    and detection taken once (`used_t` / `used_d` updated)."""
    for _, i, j in sorted(pairs):
        if i not in used_t and j not in used_d:
            used_t.add(i)
            used_d.add(j)
            yield i, j


class TextbookTracker:
    """The tracker's rules with 4x4 matrices, one track at a time ([x, y, vx, vy])."""

    def __init__(self, s: TrackerSettings) -> None:
        self.s = s
        self.r = np.diag([s.pos_x_std_m**2, s.pos_y_std_m**2, s.vel_x_std_mps**2,
                          s.vel_y_std_mps**2])
        self.tracks: list[dict] = []
        self.next_id = 1
        self.last_t: float | None = None
        self.contested = 0          # cycles where a track or a detection had two candidates
        self.resumed = 0            # tracks re-acquired after a manoeuvre

    def step(self, det: Detections, t: float) -> None:
        s = self.s
        if self.last_t is not None:
            dt = t - self.last_t
            if 0 < dt <= s.max_gap_s:
                f = np.eye(4)
                f[0, 2] = f[1, 3] = dt
                q = s.accel_std_mps2**2
                block = q * np.array([[dt**4 / 4, dt**3 / 2], [dt**3 / 2, dt**2]])
                qm = np.zeros((4, 4))
                for a in (0, 1):
                    qm[np.ix_([a, a + 2], [a, a + 2])] = block
                for tr in self.tracks:
                    tr["x"] = f @ tr["x"]
                    tr["p"] = f @ tr["p"] @ f.T + qm
            else:
                self.tracks = []
        self.last_t = t
        z = det.floats[:4].T
        rid = det.ints[0]
        pairs = []
        for i, tr in enumerate(self.tracks):
            s_inv = np.linalg.inv(tr["p"] + self.r)
            for j in range(len(det)):
                e = z[j] - tr["x"]
                d2 = float(e @ s_inv @ e)
                if d2 <= s.gate_chi2 and e[0] ** 2 + e[1] ** 2 <= s.gate_max_distance_m**2:
                    same = tr["rid"] == rid[j] and rid[j] >= 0
                    pairs.append((d2 - s.radar_id_bonus * same, i, j))
        tracks_in, dets_in = [i for _, i, _ in pairs], [j for _, _, j in pairs]
        self.contested += len(set(tracks_in)) < len(pairs) or len(set(dets_in)) < len(pairs)
        used_t: set[int] = set()
        used_d: set[int] = set()
        for i, j in _claim(pairs, used_t, used_d):
            tr = self.tracks[i]
            gain = tr["p"] @ np.linalg.inv(tr["p"] + self.r)
            tr["x"] = tr["x"] + gain @ (z[j] - tr["x"])
            tr["p"] = (np.eye(4) - gain) @ tr["p"]
            tr["rid"] = int(rid[j])
        # A confirmed track without a match re-acquires a free detection inside the
        # position-only gate: it restarts from the detection, keeping its ID and hits.
        again = []
        for i, tr in enumerate(self.tracks):
            if i in used_t or not tr["confirmed"] or s.reacquire_chi2 <= 0:
                continue
            s_pp = np.diag(tr["p"])[:2] + np.diag(self.r)[:2]
            for j in range(len(det)):
                e = z[j][:2] - tr["x"][:2]
                dv = z[j][2:] - tr["x"][2:]
                d2 = float((e * e / s_pp).sum())
                if j not in used_d and d2 <= s.reacquire_chi2 \
                        and e @ e <= s.gate_max_distance_m**2 \
                        and dv @ dv <= s.reacquire_max_dv_mps**2:
                    again.append((d2, i, j))
        for i, j in _claim(again, used_t, used_d):
            tr = self.tracks[i]
            tr["x"], tr["p"], tr["rid"] = z[j].copy(), self.r.copy(), int(rid[j])
            self.resumed += 1
        for i, tr in enumerate(self.tracks):
            tr["hits"], tr["misses"] = ((tr["hits"] + 1, 0) if i in used_t
                                        else (0, tr["misses"] + 1))
            tr["confirmed"] |= tr["hits"] >= s.confirm_hits
        self.tracks = [tr for tr in self.tracks if tr["misses"] < (
            s.delete_after_misses if tr["confirmed"] else s.delete_tentative_after_misses)]
        for j in range(len(det)):
            if j not in used_d:
                self.tracks.append({"id": self.next_id, "x": z[j].copy(), "p": self.r.copy(),
                                    "rid": int(rid[j]), "hits": 1, "misses": 0,
                                    "confirmed": s.confirm_hits <= 1})
                self.next_id += 1


@pytest.mark.parametrize(("n_targets", "bonus"), [(4, 3.0), (4, 0.0), (120, 3.0)])
def test_the_tracker_tracks_as_the_textbook_does(n_targets, bonus):
    """Noisy targets close enough to contest detections, dropouts, swapped radar IDs,
    ghosts, targets whose velocity jumps (re-acquired), a cycle with nothing and a gap
    that restarts the tracker."""
    rng = np.random.default_rng(n_targets + int(bonus))
    s = TrackerSettings(radar_id_bonus=bonus)
    tracker, textbook = KalmanTracker(s), TextbookTracker(s)
    spread = 20.0 if n_targets > 10 else 2.0
    start = np.column_stack([rng.uniform(8, 8 + spread, n_targets),
                             rng.uniform(-spread / 2, spread / 2, n_targets),
                             rng.uniform(-4, 0, n_targets), rng.uniform(-0.5, 0.5, n_targets)])
    t = 100.0
    for k in range(60):
        t += 0.075 if k != 30 else 1.0               # one gap longer than max_gap_s
        x = start.copy()
        x[:, :2] += x[:, 2:] * 0.075 * (k % 30)
        seen = rng.random(n_targets) > 0.1               # dropouts
        meas = x[seen] + rng.normal(0, [0.2, 0.2, 0.1, 0.1], (int(seen.sum()), 4))
        if k in (20, 21):
            meas[:, 3] += 4.0            # every target sets off sideways (re-acquired)
        ids = np.flatnonzero(seen)
        swap = rng.random(len(ids)) < 0.1                # the radar swaps IDs now and then
        ids[swap] = (ids[swap] + 1) % n_targets
        ghosts = int(rng.integers(0, 3))
        meas = np.vstack([meas, np.column_stack([rng.uniform(5, 40, ghosts),
                                                 rng.uniform(-8, 8, ghosts),
                                                 rng.uniform(-8, 2, ghosts), np.zeros(ghosts)])])
        ids = np.concatenate([ids, rng.integers(200, 255, ghosts)])
        if k == 45:
            meas, ids = meas[:0], ids[:0]               # nothing: every track coasts
        det = Detections.of(meas[:, 0], meas[:, 1], meas[:, 2], meas[:, 3], radar_id=ids)
        tracker.step(det, t)
        textbook.step(det, t)
        got = tracker.tracks()
        want = textbook.tracks
        assert [(g.track_id, g.hits, g.misses, g.confirmed, g.radar_object_id) for g in got] \
            == [(w["id"], w["hits"], w["misses"], w["confirmed"], w["rid"]) for w in want], \
            f"cycle {k}"
        for g, w in zip(got, want, strict=True):
            assert [g.x_m, g.y_m, g.vx_mps, g.vy_mps] == pytest.approx(w["x"], rel=1e-9,
                                                                        abs=1e-9)
            assert [g.x_var_m2, g.y_var_m2] == pytest.approx(np.diag(w["p"])[:2], rel=1e-9)
    assert tracker.resets == 1 and textbook.contested > 10
    assert tracker.resumed == textbook.resumed > 0
    assert sum(t.confirmed for t in tracker.tracks()) >= n_targets // 2
