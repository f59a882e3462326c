"""Constant-velocity Kalman tracker on [x, y, vx, vy], vectorised over tracks. Pure.

Each cycle: predict every track to the cycle time; associate detections to tracks
(Mahalanobis distance with the innovation covariance, gated by chi-square and a hard
distance cap, then greedy global nearest neighbour on the sorted costs); update matched
tracks (measurement = the detection's [x, y, vx, vy]: the ARS408 measures relative
velocity directly, so range rate is right from the first cycle); count misses; delete;
start a tentative track for every unmatched detection.

A track is confirmed once it has been updated in `confirm_hits` consecutive cycles
(the cycle that created it counts as the first); it stays confirmed while it coasts and
is deleted after `delete_after_misses` consecutive misses (tentative tracks after
`delete_tentative_after_misses`). In object mode the radar's object ID lowers the
association cost (`radar_id_bonus`) but never overrides the gate: the radar swaps IDs.

Implementation: with a constant-velocity model, white-acceleration noise per axis,
diagonal measurement noise and a diagonal initial covariance, x and y never correlate,
so the 4x4 covariance is two 2x2 blocks [[var_p, cov_pv], [cov_pv, var_v]], one per axis,
and every step is a closed-form elementwise formula over all tracks at once. numpy calls
cost microseconds each on a small CPU whatever their size (several times more on strided
data), so the whole state is one float matrix (`state`) and one integer matrix (`meta`),
a row per quantity and a column per track: a birth or a deletion is one call per matrix,
and every formula runs on contiguous rows.

Association never computes all n x m distances when there are many: the chi-square gate
bounds each position axis (|dx| <= sqrt(chi2 S_xx), |dy| <= sqrt(chi2 S_yy)), so a strip
grid (`neighbours.candidates_in_boxes`) yields the few candidates per track and only they
get the 4-d Mahalanobis distance; with few tracks and detections the dense matrix is
fewer numpy calls. The update reuses the gate's S^-1: x' = z - R S^-1 (z - x),
P' = R S^-1 P (the same as x + K (z - x), (I - K) P with K = P S^-1).

Up to `_LISTS_MAX` tracks and detections (the usual road: a few objects), a step, the
messages and the class annotation run on Python lists instead (`_step_lists`): the same
formulas in the same order, a few numpy calls instead of dozens. Both cost about the
same in a hot loop, but a radar service wakes to cold caches every cycle, where each
numpy call costs tens of microseconds (docs/performance.md).
"""

import math
from itertools import starmap

import numpy as np
import numpy.typing as npt

from common.config.radar import TrackerSettings
from common.messages.radar import RadarTrack
from services.radar.detections import DYN_PROP, OBJ_CLASS, RADAR_ID, RCS, VX, VY, Detections, X, Y
from services.radar.neighbours import candidates_in_boxes

F = npt.NDArray[np.float64]
I = npt.NDArray[np.int64]  # noqa: E741
B = npt.NDArray[np.bool_]

_EMPTY = np.zeros(0, dtype=np.int64)
# Up to this many tracks (and detections), a step, the messages and the class annotation
# run on Python lists (a few numpy calls instead of dozens): about the same cost in a hot
# loop, but a radar service wakes to cold caches every cycle, where every numpy call
# costs tens of microseconds, and with one object the whole cycle is on the chain.
_LISTS_MAX = 16
# Up to this many track x detection pairs, the gate's boxes are tested on the dense
# matrix: fewer numpy calls than the strip grid.
_DENSE_MAX = 2048

# Rows of KalmanTracker.state: the state [x, y, vx, vy]; per axis (x, y) the 2x2
# covariance block [[var_p, cov_pv], [cov_pv, var_v]]; the last detection's RCS.
POS = slice(0, 2)
VEL = slice(2, 4)
STATE = slice(0, 4)
COV = slice(4, 10)
VAR_P = slice(4, 6)
COV_PV = slice(6, 8)
VAR_V = slice(8, 10)
TRACK_RCS = 10
N_STATE = 11
# Rows of KalmanTracker.meta.
ID, HITS, MISSES, CONFIRMED, META_RADAR_ID, META_DYN_PROP, META_OBJ_CLASS = range(7)
N_META = 7
_DET_META = slice(RADAR_ID, OBJ_CLASS + 1)
assert (RADAR_ID, DYN_PROP, OBJ_CLASS) == (0, 1, 2)
# Index helpers of KalmanTracker._innovation and _update (rows of S and of the stacks).
# Index arrays, not lists: numpy converts a list on every call.
_COEF_ROWS = np.array([4, 5, 2, 3, 0, 1])            # S rows v, b, a -> alpha, beta, gamma
_AXES = np.array([0, 1, 0, 1, 0, 1])
_C1_ROWS = np.array([0, 1, 4, 5, 0, 1, 0, 1, 4, 5])  # alpha, gamma, alpha, alpha, gamma
_U2_ROWS = np.array([2, 3, 0, 1, 6, 7, 8, 9, 6, 7])  # dv, dp, cov, var_v, cov
_MESSAGE_ROWS = np.array([0, 1, 2, 3, TRACK_RCS, VAR_P.start, VAR_P.start + 1])


def covariance_step(dt: float, accel_std: float) -> tuple[F, F]:
    """(M, q) with cov' = M @ cov + q: the covariance prediction F P F^T + Q written on
    the per-axis blocks (rows var_p x/y, cov_pv x/y, var_v x/y), Q from
    piecewise-constant white acceleration."""
    m = np.eye(6)
    for axis in range(2):
        p, c, v = axis, 2 + axis, 4 + axis
        m[p, c] = 2 * dt          # var_p' = var_p + 2 dt cov + dt^2 var_v
        m[p, v] = dt * dt
        m[c, v] = dt              # cov' = cov + dt var_v
    q = accel_std**2
    noise = np.array([q * dt**4 / 4] * 2 + [q * dt**3 / 2] * 2 + [q * dt * dt] * 2)
    return m, noise[:, None]


def greedy_pairs(ti: I, di: I, cost: F) -> tuple[I, I]:
    """Greedy global nearest neighbour: pairs in order of cost (ties: lower track row,
    then lower detection row), each taken unless its track or detection already is.

    A pair alone on its track and on its detection is taken whatever its cost, so only
    the contested pairs go through the sequential loop."""
    alone = (np.bincount(ti)[ti] == 1) & (np.bincount(di)[di] == 1)
    contested = np.flatnonzero(~alone)
    if len(contested) == 0:
        return ti, di
    ct, cd = ti[contested], di[contested]
    order = np.lexsort((cd, ct, cost[contested]))
    used_t: set[int] = set()
    used_d: set[int] = set()
    mt: list[int] = []
    md: list[int] = []
    for t, d in zip(ct[order].tolist(), cd[order].tolist(), strict=True):
        if t in used_t or d in used_d:
            continue
        used_t.add(t)
        used_d.add(d)
        mt.append(t)
        md.append(d)
    return (np.concatenate([ti[alone], np.asarray(mt, dtype=np.int64)]),
            np.concatenate([di[alone], np.asarray(md, dtype=np.int64)]))


def _greedy_lists(pairs: list[tuple[float, int, int]]) -> list[tuple[int, int]]:
    """greedy_pairs on (cost, track, detection) tuples: the same pairs (a pair alone on
    its track and detection whatever its cost; the others in order of cost, then track,
    then detection)."""
    per_track: dict[int, int] = {}
    per_det: dict[int, int] = {}
    for _, i, j in pairs:
        per_track[i] = per_track.get(i, 0) + 1
        per_det[j] = per_det.get(j, 0) + 1
    out = [(i, j) for _, i, j in pairs if per_track[i] == 1 and per_det[j] == 1]
    contested = sorted(p for p in pairs if per_track[p[1]] > 1 or per_det[p[2]] > 1)
    used_t: set[int] = set()
    used_d: set[int] = set()
    for _, i, j in contested:
        if i in used_t or j in used_d:
            continue
        used_t.add(i)
        used_d.add(j)
        out.append((i, j))
    return out


class KalmanTracker:
    """`state` (11, n): a row per quantity ([x, y, vx, vy], the per-axis covariance
    blocks, the RCS), a column per track; `meta` (7, n): track ID, consecutive hits,
    consecutive misses, confirmed, and the last detection's radar ID, DynProp and class.
    Rows, not columns: numpy is several times slower on strided data."""

    def __init__(self, settings: TrackerSettings) -> None:
        self.s = settings
        r_pos = [settings.pos_x_std_m**2, settings.pos_y_std_m**2]
        r_vel = [settings.vel_x_std_mps**2, settings.vel_y_std_mps**2]
        # S = P + R on the covariance rows (cov_pv gets no noise); P0 = R.
        self._r_cov = np.array([[*r_pos, 0.0, 0.0, *r_vel]]).T
        # The update's per-block gains (see _update): position, velocity, var_p,
        # cov_pv, var_v.
        self._update_scale = np.array([[-r for r in r_pos] + [-r for r in r_vel]
                                       + r_pos + r_pos + r_vel]).T
        self._chi2 = settings.gate_chi2
        self._min_misses = min(settings.delete_after_misses,
                               settings.delete_tentative_after_misses)
        self._cap = settings.gate_max_distance_m
        self.next_id = 1
        self.last_t: float | None = None
        self.resets = 0
        # dt and its covariance step (M, q), with q also as floats (for _step_lists)
        self._step_cache: tuple[float, F, F, list[float]] | None = None
        # the same quantities as Python floats, for _step_lists
        self._r_list = [float(v) for v in self._r_cov[:, 0]]
        self._scale_list = [float(v) for v in self._update_scale[:, 0]]
        self._clear()

    def _clear(self) -> None:
        self.state: F = np.zeros((N_STATE, 0))
        self.meta: I = np.zeros((N_META, 0), dtype=np.int64)
        # Per track, from the innovation covariance S of this cycle (see _innovation).
        self._coef: F = np.zeros((6, 0))

    def __len__(self) -> int:
        return int(self.state.shape[1])

    @property
    def x(self) -> F:
        """(n, 4) [x, y, vx, vy] of every track (a view)."""
        return self.state[STATE].T

    @property
    def ids(self) -> I:
        return self.meta[ID]

    @property
    def confirmed(self) -> B:
        return self.meta[CONFIRMED].astype(np.bool_)

    def reset(self) -> None:
        self._clear()
        self.last_t = None

    def _dt(self, t_s: float) -> float:
        last, self.last_t = self.last_t, t_s
        if last is None:
            return self.s.nominal_dt_s
        dt = t_s - last
        if dt <= 0 or dt > self.s.max_gap_s:
            # A gap (bus loss) or time going backwards (replay loop): predictions from
            # before it are worthless, start again.
            if len(self):
                self.resets += 1
            self._clear()
            return self.s.nominal_dt_s
        return dt

    def predict(self, dt: float) -> None:
        """x' = F x, P' = F P F^T + Q."""
        if not len(self):
            return
        cached = self._covariance_step(dt)
        st = self.state
        st[POS] += dt * st[VEL]
        st[COV] = cached[1] @ st[COV] + cached[2]

    def _innovation(self) -> F:
        """Per track and axis, with S = P + R = [[a, b], [b, v]]: rows alpha, beta, gamma
        (2 each) = [v, 2 b, a] / det(S), so that the Mahalanobis distance of an innovation
        (dp, dv) is alpha dp^2 - beta dp dv + gamma dv^2 (summed over the axes); and the
        gate's half-widths on position, sqrt(chi2 a) capped (2, n)."""
        s = self.state[COV] + self._r_cov
        a, b, v = s[0:2], s[2:4], s[4:6]
        coef = s[_COEF_ROWS] / (a * v - b * b)[_AXES]
        coef[2:4] *= 2.0
        self._coef = coef
        return np.minimum(np.sqrt(self._chi2 * a), self._cap)

    def _gated_dense(self, det: Detections) -> tuple[I, I, F]:
        """Every track x detection pair, as matrices: fewer numpy calls when both are few."""
        diff = det.floats[STATE, None, :] - self.state[STATE, :, None]   # (4, n, m)
        dp, dv = diff[POS], diff[VEL]
        c = self._coef[:, :, None]
        d2 = (c[0:2] * dp * dp - c[2:4] * dp * dv + c[4:6] * dv * dv).sum(axis=0)
        ok = (d2 <= self._chi2) & ((dp * dp).sum(axis=0) <= self._cap**2)
        ti, di = np.nonzero(ok)
        return ti, di, d2[ti, di]

    def _gated_sparse(self, det: Detections, half: F) -> tuple[I, I, F]:
        """The pairs inside the gate's per-axis boxes first (a strip grid), the distance
        for those only."""
        st = self.state
        ti, di = candidates_in_boxes(st[X], st[Y], float(half[X].max()), half[Y], det.x, det.y)
        if len(ti) == 0:
            return _EMPTY, _EMPTY, np.zeros(0)
        d = np.take(det.floats[STATE], di, axis=1) - np.take(st[STATE], ti, axis=1)
        dp, dv = d[POS], d[VEL]
        c = np.take(self._coef, ti, axis=1)
        d2 = (c[0:2] * dp * dp - c[2:4] * dp * dv + c[4:6] * dv * dv).sum(axis=0)
        ok = np.flatnonzero((d2 <= self._chi2) & ((dp * dp).sum(axis=0) <= self._cap**2))
        return ti[ok], di[ok], d2[ok]

    def associate(self, det: Detections) -> tuple[I, I]:
        """(track rows, detection rows) matched, by greedy nearest neighbour on the gated
        Mahalanobis cost."""
        if not len(self) or not len(det):
            return _EMPTY, _EMPTY
        half = self._innovation()
        if len(self) * len(det) <= _DENSE_MAX:
            ti, di, cost = self._gated_dense(det)
        else:
            ti, di, cost = self._gated_sparse(det, half)
        if len(ti) == 0:
            return _EMPTY, _EMPTY
        if self.s.radar_id_bonus > 0:
            rid = det.ints[RADAR_ID][di]
            same = (self.meta[META_RADAR_ID][ti] == rid) & (rid >= 0)
            cost = cost - self.s.radar_id_bonus * same
        return greedy_pairs(ti, di, cost)

    def _update(self, rows: I, det: Detections, drows: I) -> None:
        """Kalman update of tracks `rows` with detections `drows` (after associate, whose
        coefficients it reuses).

        With K = P S^-1 per axis and R = diag(r_p, r_v), the update simplifies to
        x' = z - R S^-1 (z - x) and P' = R S^-1 P: position' = z_p - r_p (alpha dp - beta'
        dv), velocity' = z_v - r_v (gamma dv - beta' dp), var_p' = r_p (alpha var_p -
        beta' cov), cov' = r_p (alpha cov - beta' var_v), var_v' = r_v (gamma var_v -
        beta' cov), with beta' = beta / 2: one stacked expression for all five blocks."""
        if len(rows) == 0:
            return
        c = np.take(self.state, rows, axis=1)
        k = np.take(self._coef, rows, axis=1)
        z = np.take(det.floats, drows, axis=1)
        u1 = np.concatenate([z[STATE] - c[STATE], c[COV]])      # dp, dv, var_p, cov, var_v
        u2 = u1[_U2_ROWS].reshape(5, 2, -1)                      # dv, dp, cov, var_v, cov
        new = self._update_scale * (k[_C1_ROWS] * u1 - (0.5 * k[2:4] * u2).reshape(10, -1))
        new[STATE] += z[STATE]
        self.state[:COV.stop, rows] = new
        self.state[TRACK_RCS, rows] = z[RCS]
        self.meta[META_RADAR_ID:, rows] = np.take(det.ints[_DET_META], drows, axis=1)

    def _birth(self, det: Detections, drows: I) -> None:
        k = len(drows)
        fd = np.take(det.floats, drows, axis=1)
        new = np.empty((N_STATE, k))
        new[STATE] = fd[STATE]
        new[COV] = self._r_cov      # P0 = R
        new[TRACK_RCS] = fd[RCS]
        meta = np.zeros((N_META, k), dtype=np.int64)
        meta[ID] = np.arange(self.next_id, self.next_id + k)
        meta[HITS] = 1
        meta[CONFIRMED] = self.s.confirm_hits <= 1
        meta[META_RADAR_ID:] = np.take(det.ints[_DET_META], drows, axis=1)
        self.next_id += k
        self.state = np.concatenate([self.state, new], axis=1)
        self.meta = np.concatenate([self.meta, meta], axis=1)

    def step(self, det: Detections, t_s: float) -> None:
        """Advance to time `t_s` (seconds, the cycle's source clock) with this cycle's
        detections."""
        dt = self._dt(t_s)
        if len(self) <= _LISTS_MAX and len(det) <= _LISTS_MAX:
            self._step_lists(det, dt)
            return
        self.predict(dt)
        rows, drows = self.associate(det)
        self._update(rows, det, drows)
        if len(self):
            self._count(rows)
        if len(rows) < len(det):
            unmatched = np.ones(len(det), dtype=np.bool_)
            unmatched[drows] = False
            self._birth(det, np.flatnonzero(unmatched))

    def _step_lists(self, det: Detections, dt: float) -> None:
        """`step` on Python lists, for a few tracks and detections: the same formulas in
        the same order as the array path (only the covariance prediction, a matrix
        product there, may round differently in the last bit)."""
        s = self.s
        n, m = len(self), len(det)
        if not n and not m:
            return          # an empty road: nothing to predict, match or start
        st: list[list[float]] = self.state.tolist() if n else [[] for _ in range(N_STATE)]
        meta: list[list[int]] = self.meta.tolist() if n else [[] for _ in range(N_META)]
        df: list[list[float]] = det.floats.tolist() if m else []
        di: list[list[int]] = det.ints.tolist() if m else []
        r = self._r_list
        if n:
            q = self._covariance_step(dt)[3]
            two_dt, dt2 = 2 * dt, dt * dt
            for a in (0, 1):
                pos, vel, vp, cv, vv = st[a], st[2 + a], st[4 + a], st[6 + a], st[8 + a]
                qp, qc, qv = q[a], q[2 + a], q[4 + a]
                for j in range(n):
                    pos[j] = pos[j] + dt * vel[j]
                    p, c, v = vp[j], cv[j], vv[j]
                    vp[j] = p + two_dt * c + dt2 * v + qp
                    cv[j] = c + dt * v + qc
                    vv[j] = v + qv
        matched: list[tuple[int, int]] = []
        if n and m:
            # per track and axis: alpha, beta, gamma of S^-1 (see _innovation)
            coef = []
            for j in range(n):
                k = []
                for a in (0, 1):
                    sa = st[4 + a][j] + r[a]
                    sb = st[6 + a][j] + r[2 + a]
                    sv = st[8 + a][j] + r[4 + a]
                    d = sa * sv - sb * sb
                    k.append((sv / d, sb / d * 2.0, sa / d))
                coef.append(k)
            cap2 = self._cap**2
            bonus = s.radar_id_bonus
            pairs: list[tuple[float, int, int]] = []
            for i in range(n):
                (ax, bx, gx), (ay, by, gy) = coef[i]
                x, y, vx, vy = st[0][i], st[1][i], st[2][i], st[3][i]
                for j in range(m):
                    dpx, dpy = df[X][j] - x, df[Y][j] - y
                    dvx, dvy = df[VX][j] - vx, df[VY][j] - vy
                    d2 = ((ax * dpx * dpx - bx * dpx * dvx + gx * dvx * dvx)
                          + (ay * dpy * dpy - by * dpy * dvy + gy * dvy * dvy))
                    if d2 <= self._chi2 and dpx * dpx + dpy * dpy <= cap2:
                        if bonus > 0:
                            rid = di[RADAR_ID][j]
                            d2 = d2 - bonus * (meta[META_RADAR_ID][i] == rid and rid >= 0)
                        pairs.append((d2, i, j))
            matched = _greedy_lists(pairs)
            for i, j in matched:
                for a in (0, 1):
                    alpha, beta, gamma = coef[i][a]
                    hb = 0.5 * beta
                    rp, rv = self._scale_list[4 + a], self._scale_list[8 + a]
                    # detection rows X, Y, VX, VY and state rows x, y, vx, vy coincide
                    dp, dv = df[X + a][j] - st[a][i], df[VX + a][j] - st[2 + a][i]
                    p, c, v = st[4 + a][i], st[6 + a][i], st[8 + a][i]
                    st[a][i] = -rp * (alpha * dp - hb * dv) + df[X + a][j]
                    st[2 + a][i] = -rv * (gamma * dv - hb * dp) + df[VX + a][j]
                    st[4 + a][i] = rp * (alpha * p - hb * c)
                    st[6 + a][i] = rp * (alpha * c - hb * v)
                    st[8 + a][i] = rv * (gamma * v - hb * c)
                st[TRACK_RCS][i] = df[RCS][j]
                for row in (META_RADAR_ID, META_DYN_PROP, META_OBJ_CLASS):
                    meta[row][i] = di[row - META_RADAR_ID][j]
        if n:
            st, meta = self._count_lists(st, meta, {i for i, _ in matched})
        taken = {j for _, j in matched}
        for j in range(m):
            if j in taken:
                continue
            for row, value in enumerate((df[X][j], df[Y][j], df[VX][j], df[VY][j], *r,
                                         df[RCS][j])):
                st[row].append(value)
            for row, value in enumerate((self.next_id, 1, 0, int(s.confirm_hits <= 1),
                                         di[RADAR_ID][j], di[DYN_PROP][j], di[OBJ_CLASS][j])):
                meta[row].append(value)
            self.next_id += 1
        if st[0]:
            self.state = np.array(st, dtype=np.float64)
            self.meta = np.array(meta, dtype=np.int64)
        else:
            self._clear()

    def _covariance_step(self, dt: float) -> tuple[float, F, F, list[float]]:
        """(dt, M, q, q as floats) of covariance_step, cached while dt stays the same."""
        cached = self._step_cache
        if cached is None or cached[0] != dt:
            m, q = covariance_step(dt, self.s.accel_std_mps2)
            cached = self._step_cache = (dt, m, q, q[:, 0].tolist())
        return cached

    def _count_lists(self, st: list[list[float]], meta: list[list[int]], rows: set[int]
                     ) -> tuple[list[list[float]], list[list[int]]]:
        """`_count` on lists: hits, misses, confirmation, deletion."""
        s = self.s
        hits, misses, confirmed = meta[HITS], meta[MISSES], meta[CONFIRMED]
        n = len(hits)
        for j in range(n):
            if j in rows:
                hits[j] += 1
                misses[j] = 0
            else:
                hits[j] = 0
                misses[j] += 1
            confirmed[j] |= hits[j] >= s.confirm_hits
        if len(rows) == n or max(misses) < self._min_misses:
            return st, meta
        keep = [misses[j] < (s.delete_after_misses if confirmed[j] > 0
                             else s.delete_tentative_after_misses) for j in range(n)]
        if all(keep):
            return st, meta
        return ([[v for v, k in zip(row, keep, strict=True) if k] for row in st],
                [[v for v, k in zip(row, keep, strict=True) if k] for row in meta])

    def _count(self, rows: I) -> None:
        """Hits and misses after an update of `rows`; confirmation; deletion."""
        s = self.s
        meta = self.meta
        hits, misses = meta[HITS], meta[MISSES]
        hits += 1
        misses += 1
        misses[rows] = 0
        if len(rows) < len(self):
            matched = np.zeros(len(self), dtype=np.bool_)
            matched[rows] = True
            hits *= matched
        confirmed = meta[CONFIRMED]
        confirmed |= hits >= s.confirm_hits
        if len(rows) == len(self) or misses.max() < self._min_misses:
            return                       # nobody reached a deletion limit
        limit = np.where(confirmed > 0, s.delete_after_misses, s.delete_tentative_after_misses)
        keep = misses < limit
        if not keep.all():
            self.state = np.compress(keep, self.state, axis=1)
            self.meta = np.compress(keep, meta, axis=1)

    def annotate_class(self, det: Detections) -> None:
        """Set the object class of the tracks updated or born this cycle from `det` (the
        cycle's detections, classes attached after the tracker ran), by radar ID."""
        if not len(self) or not len(det):
            return
        if len(self) <= _LISTS_MAX and len(det) <= _LISTS_MAX and self._annotate_class_lists(det):
            return
        lut = np.full(256, -1, dtype=np.int64)
        lut[det.radar_id] = det.ints[OBJ_CLASS]
        meta = self.meta
        fresh = (meta[MISSES] == 0) & (meta[META_RADAR_ID] >= 0)
        meta[META_OBJ_CLASS, fresh] = lut[meta[META_RADAR_ID, fresh]]

    def _annotate_class_lists(self, det: Detections) -> bool:
        """annotate_class for a few tracks and detections (the same result, bit for bit:
        the last detection of a radar ID wins, as in the look-up table); False, with
        nothing done, for a radar ID outside 0..255 (no radar sends one: the table's
        indexing decides)."""
        ids, classes = det.ints[RADAR_ID].tolist(), det.ints[OBJ_CLASS].tolist()
        if min(ids) < 0 or max(ids) > 255:
            return False
        by_id = dict(zip(ids, classes, strict=True))
        meta = self.meta
        rows = meta.tolist()
        for j, (misses, rid) in enumerate(zip(rows[MISSES], rows[META_RADAR_ID], strict=True)):
            if misses == 0 and rid >= 0:
                meta[META_OBJ_CLASS, j] = by_id.get(rid, -1)
        return True

    def tracks(self) -> list[RadarTrack]:
        """Every track, confirmed or not, as messages."""
        if not len(self):
            return []
        if len(self) <= _LISTS_MAX:
            return self._tracks_lists()
        st = self.state
        r = np.hypot(st[0], st[1])
        rr = np.divide(st[0] * st[2] + st[1] * st[3], r, out=np.zeros_like(r), where=r > 0)
        # One tolist() per matrix (of the rows a message carries): per-element
        # conversions would dominate.
        x, y, vx, vy, rcs, x_var, y_var = st[_MESSAGE_ROWS].tolist()
        m = self.meta.tolist()
        return list(starmap(RadarTrack, zip(
            m[ID], x, y, vx, vy, r.tolist(), rr.tolist(), rcs,
            (self.meta[CONFIRMED] > 0).tolist(), m[HITS], m[MISSES], x_var, y_var,
            m[META_RADAR_ID], m[META_DYN_PROP], m[META_OBJ_CLASS], strict=True,
        )))

    def _tracks_lists(self) -> list[RadarTrack]:
        """tracks() for a few tracks: the same messages (the range by math.hypot, which
        may differ from numpy's in the last bit)."""
        st = self.state.tolist()
        m = self.meta.tolist()
        out = []
        for j, (x, y, vx, vy) in enumerate(zip(st[0], st[1], st[2], st[3], strict=True)):
            r = math.hypot(x, y)
            out.append(RadarTrack(
                m[ID][j], x, y, vx, vy, r, (x * vx + y * vy) / r if r > 0 else 0.0,
                st[TRACK_RCS][j], m[CONFIRMED][j] > 0, m[HITS][j], m[MISSES][j],
                st[VAR_P.start][j], st[VAR_P.start + 1][j], m[META_RADAR_ID][j],
                m[META_DYN_PROP][j], m[META_OBJ_CLASS][j]))
        return out
