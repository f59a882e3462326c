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

With a constant-velocity model, white-acceleration noise per axis and diagonal
measurement and initial noise, x and y never correlate: the 4x4 covariance is two 2x2
blocks [[var_p, cov_pv], [cov_pv, var_v]], one per axis, and every step is a closed-form
formula over all tracks at once. The state is one float matrix (`state`) and one integer
matrix (`meta`), a row per quantity and a column per track.

The chi-square gate bounds each position axis (|dx| <= sqrt(chi2 S_xx), |dy| <=
sqrt(chi2 S_yy)), so only the pairs inside those boxes get the 4-d Mahalanobis distance;
with many tracks and detections a strip grid (`neighbours.candidates_in_boxes`) finds
them without looking at every pair. The update reuses the gate's S^-1:
x' = z - R S^-1 (z - x), P' = R S^-1 P (the same as x + K (z - x), (I - K) P with
K = P S^-1).
"""

import numpy as np
import numpy.typing as npt

from common.config.radar import TrackerSettings
from common.messages.radar import RadarTrack
from services.radar.detections import OBJ_CLASS, RADAR_ID, RCS, VX, VY, Detections, X, Y
from services.radar.neighbours import candidates_in_boxes

F = npt.NDArray[np.float64]
I = npt.NDArray[np.int64]  # noqa: E741
B = npt.NDArray[np.bool_]

_EMPTY = np.zeros(0, dtype=np.int64)
# Up to this many track x detection pairs (16 x 16, the usual road) the gate tests every
# pair; above, it finds the candidates on a strip grid first, which costs more for a few
# tracks and less from about 20 x 20 on.
_DENSE_MAX = 256

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
# Detection rows carried into a track's meta rows META_RADAR_ID.. (radar ID, DynProp, class)
_DET_META = slice(RADAR_ID, OBJ_CLASS + 1)
# Detection rows of the measurement [x, y] and [vx, vy]: the same rows as the state's.
_Z_POS = slice(X, Y + 1)
_Z_VEL = slice(VX, VY + 1)
assert (X, Y, VX, VY) == (0, 1, 2, 3) and (_Z_POS, _Z_VEL) == (POS, VEL)


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


class KalmanTracker:
    """`state` (11, n): a row per quantity ([x, y, vx, vy], the per-axis covariance
    blocks, the RCS), a column per track; `meta` (7, n): track ID, consecutive hits,
    consecutive misses, confirmed, and the last detection's radar ID, DynProp and class."""

    def __init__(self, settings: TrackerSettings) -> None:
        self.s = settings
        # Measurement noise per axis (x, y) as columns: R = diag(r_pos, r_vel); P0 = R.
        self._r_pos = np.array([[settings.pos_x_std_m**2], [settings.pos_y_std_m**2]])
        self._r_vel = np.array([[settings.vel_x_std_mps**2], [settings.vel_y_std_mps**2]])
        self._chi2 = settings.gate_chi2
        self._cap = settings.gate_max_distance_m
        self.next_id = 1
        self.last_t: float | None = None
        self.resets = 0
        self._clear()

    def _clear(self) -> None:
        self.state: F = np.zeros((N_STATE, 0))
        self.meta: I = np.zeros((N_META, 0), dtype=np.int64)
        # S^-1 = [[alpha, -beta], [-beta, gamma]] per axis (rows x, y) and track, from
        # the innovation covariance S of this cycle (see _innovation).
        self._alpha: F = np.zeros((2, 0))
        self._beta: F = np.zeros((2, 0))
        self._gamma: F = np.zeros((2, 0))

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

    def step(self, det: Detections, t_s: float) -> None:
        """Advance to time `t_s` (seconds, the cycle's source clock) with this cycle's
        detections."""
        last, self.last_t = self.last_t, t_s
        if last is not None:
            dt = t_s - last
            if 0 < dt <= self.s.max_gap_s:
                self.predict(dt)
            elif len(self):
                # A gap (bus loss) or time going backwards (replay loop): predictions
                # from before it are worthless, start again.
                self.resets += 1
                self._clear()
        rows, drows = self.associate(det)
        self._update(rows, det, drows)
        self._count(rows)
        if len(rows) < len(det):
            unmatched = np.ones(len(det), dtype=np.bool_)
            unmatched[drows] = False
            self._birth(det, np.flatnonzero(unmatched))

    def predict(self, dt: float) -> None:
        """x' = F x, P' = F P F^T + Q, with Q from piecewise-constant white acceleration,
        on each axis's block."""
        if not len(self):
            return
        st = self.state
        q = self.s.accel_std_mps2**2
        st[POS] = st[POS] + dt * st[VEL]
        p, c, v = st[VAR_P], st[COV_PV], st[VAR_V]
        st[VAR_P] = p + 2 * dt * c + dt * dt * v + q * dt**4 / 4
        st[COV_PV] = c + dt * v + q * dt**3 / 2
        st[VAR_V] = v + q * dt * dt

    def _innovation(self) -> F:
        """S = P + R = [[a, b], [b, v]] per track and axis: stores S^-1 (alpha = v / det,
        beta = b / det, gamma = a / det), and returns the gate's half-widths on position,
        sqrt(chi2 a) capped (2, n)."""
        st = self.state
        a = st[VAR_P] + self._r_pos
        b = st[COV_PV]
        v = st[VAR_V] + self._r_vel
        det = a * v - b * b
        self._alpha, self._beta, self._gamma = v / det, b / det, a / det
        return np.minimum(np.sqrt(self._chi2 * a), self._cap)

    def _gated(self, ti: I, di: I, dp: F, dv: F) -> tuple[I, I, F]:
        """The pairs (track ti, detection di) with innovation dp, dv (2, k) inside the
        gate, and their Mahalanobis distance."""
        a, b, g = (np.take(c, ti, axis=1) for c in (self._alpha, self._beta, self._gamma))
        d2 = (a * dp * dp - 2.0 * b * dp * dv + g * dv * dv).sum(axis=0)
        ok = np.flatnonzero((d2 <= self._chi2) & ((dp * dp).sum(axis=0) <= self._cap**2))
        return ti[ok], di[ok], d2[ok]

    def _candidates(self, det: Detections, half: F) -> tuple[I, I]:
        """Track x detection pairs that may lie inside the gate: every pair when there
        are few, else those inside the gate's per-axis boxes (a strip grid)."""
        n, m = len(self), len(det)
        if n * m <= _DENSE_MAX:
            return np.repeat(np.arange(n), m), np.tile(np.arange(m), n)
        st = self.state
        return candidates_in_boxes(st[X], st[Y], float(half[X].max()), half[Y], det.x, det.y)

    def associate(self, det: Detections) -> tuple[I, I]:
        """(track rows, detection rows) matched, by greedy nearest neighbour on the gated
        Mahalanobis cost."""
        if not len(self) or not len(det):
            return _EMPTY, _EMPTY
        ti, di = self._candidates(det, self._innovation())
        if len(ti) == 0:
            return _EMPTY, _EMPTY
        diff = np.take(det.floats[STATE], di, axis=1) - np.take(self.state[STATE], ti, axis=1)
        ti, di, cost = self._gated(ti, di, diff[POS], diff[VEL])
        if len(ti) == 0:
            return _EMPTY, _EMPTY
        if self.s.radar_id_bonus > 0:
            rid = det.ints[RADAR_ID][di]
            same = (self.meta[META_RADAR_ID][ti] == rid) & (rid >= 0)
            cost = cost - self.s.radar_id_bonus * same
        return greedy_pairs(ti, di, cost)

    def _update(self, rows: I, det: Detections, drows: I) -> None:
        """Kalman update of tracks `rows` with detections `drows`, after `associate`,
        whose S^-1 it reuses.

        With K = P S^-1 per axis and R = diag(r_p, r_v) the update is x' = z - R S^-1 (z
        - x), P' = R S^-1 P, written out on each axis's block below."""
        if len(rows) == 0:
            return
        alpha, beta, gamma = (np.take(c, rows, axis=1)
                              for c in (self._alpha, self._beta, self._gamma))
        rp, rv = self._r_pos, self._r_vel
        old = np.take(self.state, rows, axis=1)
        z = np.take(det.floats, drows, axis=1)
        zp, zv = z[_Z_POS], z[_Z_VEL]
        dp, dv = zp - old[POS], zv - old[VEL]
        p, c, v = old[VAR_P], old[COV_PV], old[VAR_V]
        new = np.empty((N_STATE, len(rows)))
        new[POS] = -rp * (alpha * dp - beta * dv) + zp
        new[VEL] = -rv * (gamma * dv - beta * dp) + zv
        new[VAR_P] = rp * (alpha * p - beta * c)
        new[COV_PV] = rp * (alpha * c - beta * v)
        new[VAR_V] = rv * (gamma * v - beta * c)
        new[TRACK_RCS] = z[RCS]
        self.state[:, rows] = new
        self.meta[META_RADAR_ID:, rows] = np.take(det.ints[_DET_META], drows, axis=1)

    def _count(self, rows: I) -> None:
        """Hits and misses after an update of `rows`; confirmation; deletion."""
        if not len(self):
            return
        s, meta = self.s, self.meta
        matched = np.zeros(len(self), dtype=np.bool_)
        matched[rows] = True
        hits, misses = meta[HITS], meta[MISSES]      # views: updated in place
        hits += 1
        hits *= matched                  # consecutive: a miss starts again from 0
        misses += 1
        misses *= ~matched
        meta[CONFIRMED] |= hits >= s.confirm_hits
        limit = np.where(meta[CONFIRMED] > 0, s.delete_after_misses,
                         s.delete_tentative_after_misses)
        keep = misses < limit
        if not keep.all():
            self.state = np.compress(keep, self.state, axis=1)
            self.meta = np.compress(keep, meta, axis=1)

    def _birth(self, det: Detections, drows: I) -> None:
        k = len(drows)
        fd = np.take(det.floats, drows, axis=1)
        new = np.empty((N_STATE, k))
        new[STATE] = fd[STATE]
        new[VAR_P] = self._r_pos      # P0 = R
        new[COV_PV] = 0.0
        new[VAR_V] = self._r_vel
        new[TRACK_RCS] = fd[RCS]
        meta = np.zeros((N_META, k), dtype=np.int64)
        meta[ID] = np.arange(self.next_id, self.next_id + k)
        meta[HITS] = 1
        meta[CONFIRMED] = self.s.confirm_hits <= 1
        meta[META_RADAR_ID:] = np.take(det.ints[_DET_META], drows, axis=1)
        self.next_id += k
        self.state = np.concatenate([self.state, new], axis=1)
        self.meta = np.concatenate([self.meta, meta], axis=1)

    def annotate_class(self, det: Detections) -> None:
        """Set the object class of the tracks updated or born this cycle from `det` (the
        cycle's detections, classes attached after the tracker ran), by radar ID."""
        if not len(self) or not len(det):
            return
        lut = np.full(256, -1, dtype=np.int64)
        lut[det.radar_id] = det.ints[OBJ_CLASS]
        meta = self.meta
        fresh = (meta[MISSES] == 0) & (meta[META_RADAR_ID] >= 0)
        meta[META_OBJ_CLASS, fresh] = lut[meta[META_RADAR_ID, fresh]]

    def tracks(self) -> list[RadarTrack]:
        """Every track, confirmed or not, as messages."""
        if not len(self):
            return []
        st = self.state
        r = np.hypot(st[X], st[Y])
        rr = np.divide(st[X] * st[VX] + st[Y] * st[VY], r, out=np.zeros_like(r), where=r > 0)
        x, y, vx, vy = st[STATE].tolist()
        x_var, y_var = st[VAR_P].tolist()
        m = self.meta.tolist()
        return [RadarTrack(*fields) for fields in zip(
            m[ID], x, y, vx, vy, r.tolist(), rr.tolist(), st[TRACK_RCS].tolist(),
            (self.meta[CONFIRMED] > 0).tolist(), m[HITS], m[MISSES], x_var, y_var,
            m[META_RADAR_ID], m[META_DYN_PROP], m[META_OBJ_CLASS], strict=True)]
