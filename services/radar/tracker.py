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

A confirmed track that no detection matched, with a detection that no track took where
the track is (inside the gate on position alone, `reacquire_chi2`, with a velocity at
most `reacquire_max_dv_mps` from the track's), takes that detection's state and keeps
its ID: a target that changes its motion abruptly (a cyclist
waiting beside the road who sets off across it) falls out of the 4-d gate on velocity,
and a new ID would throw away everything known of it (its confirmation here; in fusion
its camera evidence and the cycles of sideways motion a crossing prediction needs).

With a constant-velocity model, white-acceleration noise per axis and diagonal
measurement and initial noise, x and y never correlate: the 4x4 covariance is two 2x2
blocks [[var_p, cov_pv], [cov_pv, var_v]], one per axis, and every step is a closed-form
formula over all tracks at once. Each quantity is a (2, n) array, row 0 the x axis and
row 1 the y axis, a column per track: `pos` (x, y), `vel` (vx, vy), `var_p`, `cov_pv`,
`var_v`; they are rows of one float matrix (`state`, beside the integer matrix `meta`),
so that deleting or adding tracks is one operation on each matrix. With the noise q of
piecewise-constant white acceleration (variance w), the prediction over dt is, per axis:

    pos' = pos + dt vel
    var_p' = var_p + 2 dt cov_pv + dt^2 var_v + w dt^4 / 4
    cov_pv' = cov_pv + dt var_v + w dt^3 / 2
    var_v' = var_v + w dt^2

The chi-square gate bounds each position axis (|dx| <= sqrt(chi2 S_xx), |dy| <=
sqrt(chi2 S_yy)), so only the pairs inside those boxes get the 4-d Mahalanobis distance;
with many tracks and detections a strip grid (`neighbours.candidates_in_boxes`) finds
them without looking at every pair. Per axis, with S = P + R = [[a, b], [b, v]] and the
innovation e = z - x = [dp; dv]:

    S^-1 = [[inv_pp, inv_pv], [inv_pv, inv_vv]] = [[v, -b], [-b, a]] / (a v - b^2)
    d^2 = e' S^-1 e, summed over both axes

The update reuses the gate's S^-1: x' = z - R S^-1 e and P' = R S^-1 P (the same as
x + K e and (I - K) P with K = P S^-1), with R = diag(r_p, r_v) per axis:

    pos' = z_p - r_p (inv_pp dp + inv_pv dv)
    vel' = z_v - r_v (inv_pv dp + inv_vv dv)
    var_p' = r_p (inv_pp var_p + inv_pv cov_pv)
    cov_pv' = r_p (inv_pp cov_pv + inv_pv var_v)
    var_v' = r_v (inv_pv cov_pv + inv_vv var_v)
"""

from functools import lru_cache
from itertools import starmap

import numpy as np
import numpy.typing as npt

from aeb_radar_camera.common.config.radar import TrackerSettings
from aeb_radar_camera.common.messages.radar import RadarTrack
from aeb_radar_camera.services.radar.detections import (
    OBJ_CLASS,
    RADAR_ID,
    RCS,
    VX,
    VY,
    Detections,
    X,
    Y,
)
from aeb_radar_camera.services.radar.neighbours import candidates_in_boxes

F = npt.NDArray[np.float64]
I = npt.NDArray[np.int64]  # noqa: E741
B = npt.NDArray[np.bool_]

_EMPTY = np.zeros(0, dtype=np.int64)
# Up to this many track x detection pairs the gate tests every pair; above, it finds the
# candidates on a strip grid first, which costs more for a few tracks and less for many.
_DENSE_MAX = 2048

# Rows of KalmanTracker.state: the state [x, y, vx, vy] and the last detection's RCS (the
# rows of a detection's floats, in the same order); the per-axis (x, y) covariance
# entries var_p, cov_pv, var_v, two rows each.
POS = slice(0, 2)
VEL = slice(2, 4)
STATE = slice(0, 4)
TRACK_RCS = 4
MEASURED = slice(0, 5)
COV = slice(5, 11)
VAR_P = slice(5, 7)
COV_PV = slice(7, 9)
VAR_V = slice(9, 11)
N_STATE = 11
assert (X, Y, VX, VY, RCS) == (0, 1, 2, 3, TRACK_RCS)
# Rows of KalmanTracker.meta.
ID, HITS, MISSES, CONFIRMED, META_RADAR_ID, META_DYN_PROP, META_OBJ_CLASS = range(7)
N_META = 7
# Detection rows carried into a track's meta rows META_RADAR_ID.. (radar ID, DynProp, class)
_DET_META = slice(RADAR_ID, OBJ_CLASS + 1)

# The object class by radar ID (8 bits) before a cycle's classes are looked up.
_NO_CLASS_BY_ID = np.full(256, -1, dtype=np.int64)
# A track at the origin has no range rate: its numerator is 0, so 0 / _TINY = 0.
_TINY = np.finfo(np.float64).tiny


@lru_cache(maxsize=512)
def _every_pair(n: int, m: int) -> tuple[I, I]:
    """(track rows, detection rows) of every pair of n tracks and m detections."""
    return np.repeat(np.arange(n), m), np.tile(np.arange(m), n)


def _one_to_one(ti: I, di: I) -> bool:
    """No track and no detection in two pairs."""
    t_rows, d_rows = ti.tolist(), di.tolist()
    return len(set(t_rows)) == len(t_rows) and len(set(d_rows)) == len(d_rows)


def greedy_pairs(ti: I, di: I, cost: F) -> tuple[I, I]:
    """Greedy global nearest neighbour: pairs in order of cost (ties: lower track row,
    then lower detection row), each taken unless its track or detection already is.

    A pair alone on its track and on its detection is taken whatever its cost, so only
    the contested pairs go through the sequential loop."""
    alone = (np.bincount(ti).take(ti) == 1) & (np.bincount(di).take(di) == 1)
    contested = (~alone).nonzero()[0]
    ct, cd = ti.take(contested), di.take(contested)
    order = np.lexsort((cd, ct, cost.take(contested)))
    used_t: set[int] = set()
    used_d: set[int] = set()
    mt: list[int] = []
    md: list[int] = []
    for t, d in zip(ct.take(order).tolist(), cd.take(order).tolist(), strict=True):
        if t in used_t or d in used_d:
            continue
        used_t.add(t)
        used_d.add(d)
        mt.append(t)
        md.append(d)
    return (np.concatenate([ti.compress(alone), np.array(mt, dtype=np.int64)]),
            np.concatenate([di.compress(alone), np.array(md, dtype=np.int64)]))


class KalmanTracker:
    """`state` (11, n): a row per quantity ([x, y, vx, vy], the RCS, the per-axis
    covariance blocks), a column per track; `meta` (7, n): track ID, consecutive hits,
    consecutive misses, confirmed, and the last detection's radar ID, DynProp and class."""

    def __init__(self, settings: TrackerSettings) -> None:
        self.s = settings
        r_pos = [settings.pos_x_std_m**2, settings.pos_y_std_m**2]
        r_vel = [settings.vel_x_std_mps**2, settings.vel_y_std_mps**2]
        # Measurement noise R = diag(r_p, r_v) per axis, as (2, 1) columns (x, y); a new
        # track's covariance rows, P0 = R.
        self._r_p = np.array([r_pos]).T
        self._r_v = np.array([r_vel]).T
        self._p0 = np.array([[*r_pos, 0.0, 0.0, *r_vel]]).T
        # A new track's meta rows ID..CONFIRMED (the ID set at birth).
        self._meta_born = np.array([[0, 1, 0, int(settings.confirm_hits <= 1)]]).T
        # Misses that delete a track, by its CONFIRMED row (0, 1).
        self._miss_limits = np.array([settings.delete_tentative_after_misses,
                                      settings.delete_after_misses])
        self._chi2 = settings.gate_chi2
        self._cap = settings.gate_max_distance_m
        self.next_id = 1
        self.last_t: float | None = None
        self.resets = 0
        self.resumed = 0             # tracks re-acquired after a manoeuvre (reacquire)
        self._clear()

    def _clear(self) -> None:
        self.state: F = np.zeros((N_STATE, 0))
        self.meta: I = np.zeros((N_META, 0), dtype=np.int64)
        # S^-1 per axis and track from this cycle's innovation covariance: (3, 2, n), the
        # entries inv_pp, inv_pv, inv_vv.
        self._s_inv: F = np.zeros((3, 2, 0))

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
        if last is not None and len(self):
            dt = t_s - last
            if 0 < dt <= self.s.max_gap_s:
                self.predict(dt)
            else:
                # A gap (bus loss) or time going backwards (replay loop): predictions
                # from before it are worthless, start again.
                self.resets += 1
                self._clear()
        if len(self):
            rows, drows = self.associate(det)
            self._update(rows, det, drows)
            again, dagain = self.reacquire(det, rows, drows)
            if len(again):
                self._restart(again, det, dagain)
                rows, drows = np.concatenate([rows, again]), np.concatenate([drows, dagain])
            self._count(rows)
        else:
            drows = _EMPTY
        if len(drows) < len(det):
            taken = np.bincount(drows, minlength=len(det))
            self._birth(det, (taken == 0).nonzero()[0] if len(drows) else None)

    def predict(self, dt: float) -> None:
        """x' = F x, P' = F P F^T + Q, on every track (in place, per axis)."""
        st = self.state
        pos, vel, var_p, cov_pv, var_v = st[POS], st[VEL], st[VAR_P], st[COV_PV], st[VAR_V]
        w = self.s.accel_std_mps2**2
        pos += dt * vel
        var_p += 2 * dt * cov_pv + dt * dt * var_v + w * dt**4 / 4
        cov_pv += dt * var_v + w * dt**3 / 2
        var_v += w * dt * dt

    def _innovation(self) -> None:
        """S^-1 per track and axis from S = P + R = [[a, b], [b, v]] (`_s_inv`)."""
        st = self.state
        a, b, v = st[VAR_P] + self._r_p, st[COV_PV], st[VAR_V] + self._r_v
        det = a * v - b * b
        self._s_inv = np.array([v, -b, a]) / det

    def _candidates(self, det: Detections) -> tuple[I, I]:
        """Track x detection pairs that may lie inside the gate: every pair when there
        are few, else those inside the gate's per-axis boxes, sqrt(chi2 S_pp) capped
        (a strip grid)."""
        n, m = len(self), len(det)
        if n * m <= _DENSE_MAX:
            return _every_pair(n, m)
        st = self.state
        half = np.minimum(np.sqrt(self._chi2 * (st[VAR_P] + self._r_p)), self._cap)
        return candidates_in_boxes(st[X], st[Y], float(half[0].max()), half[1], det.x, det.y)

    def associate(self, det: Detections) -> tuple[I, I]:
        """(track rows, detection rows) matched, by greedy nearest neighbour on the gated
        Mahalanobis cost."""
        if not len(self) or not len(det):
            return _EMPTY, _EMPTY
        self._innovation()
        ti, di = self._candidates(det)
        if len(ti) == 0:
            return _EMPTY, _EMPTY
        inv_pp, inv_pv, inv_vv = self._s_inv.take(ti, axis=2)
        e = det.floats[STATE].take(di, axis=1) - self.state[STATE].take(ti, axis=1)
        dp, dv = e[POS], e[VEL]
        d2 = (dp * (inv_pp * dp + inv_pv * dv) + dv * (inv_pv * dp + inv_vv * dv)).sum(axis=0)
        inside = ((d2 <= self._chi2) & ((dp * dp).sum(axis=0) <= self._cap**2)).nonzero()[0]
        if len(inside) == 0:
            return _EMPTY, _EMPTY
        ti, di = ti.take(inside), di.take(inside)
        if _one_to_one(ti, di):
            return ti, di                # nothing to choose: the costs do not matter
        cost = d2.take(inside)
        if self.s.radar_id_bonus > 0:
            rid = det.ints[RADAR_ID].take(di)
            same = (self.meta[META_RADAR_ID].take(ti) == rid) & (rid >= 0)
            cost = cost - self.s.radar_id_bonus * same
        return greedy_pairs(ti, di, cost)

    def reacquire(self, det: Detections, rows: I, drows: I) -> tuple[I, I]:
        """(track rows, detection rows) re-acquired after a manoeuvre: a confirmed track
        that no detection matched this cycle (`rows` are the matched tracks, `drows`
        their detections) and a detection no track took, inside the gate on position
        alone (`reacquire_chi2`, 2 degrees of freedom; the distance cap) whose velocity
        differs by at most `reacquire_max_dv_mps` (a larger jump within one cycle is
        another object: a car ahead does not stop dead, a post beside it does not
        move), by greedy nearest neighbour. None when `reacquire_chi2` is 0."""
        chi2 = self.s.reacquire_chi2
        if chi2 <= 0.0 or not len(self) or not len(det):
            return _EMPTY, _EMPTY
        lost = self.meta[CONFIRMED].astype(np.bool_)
        lost[rows] = False
        free = np.ones(len(det), dtype=np.bool_)
        free[drows] = False
        t_rows, d_rows = lost.nonzero()[0], free.nonzero()[0]
        if not len(t_rows) or not len(d_rows):
            return _EMPTY, _EMPTY
        pt, pd = _every_pair(len(t_rows), len(d_rows))
        ti, di = t_rows.take(pt), d_rows.take(pd)
        dp = det.floats[POS].take(di, axis=1) - self.state[POS].take(ti, axis=1)
        s_pp = (self.state[VAR_P] + self._r_p).take(ti, axis=1)
        d2 = (dp * dp / s_pp).sum(axis=0)
        dv = det.floats[VEL].take(di, axis=1) - self.state[VEL].take(ti, axis=1)
        inside = ((d2 <= chi2) & ((dp * dp).sum(axis=0) <= self._cap**2)
                  & ((dv * dv).sum(axis=0) <= self.s.reacquire_max_dv_mps**2)).nonzero()[0]
        if len(inside) == 0:
            return _EMPTY, _EMPTY
        return greedy_pairs(ti.take(inside), di.take(inside), d2.take(inside))

    def _restart(self, rows: I, det: Detections, drows: I) -> None:
        """Tracks `rows` take detections `drows` as a new track would (state measured,
        covariance P0) and keep their ID, hits and confirmation: the ARS408 measures
        velocity, so a detection where the track is, whose velocity the 4-d gate
        refuses, is the same object changing its motion (a cyclist setting off across
        the road), and what was learnt of the object under its ID (consumers key their
        history on it) must not start again with a new one."""
        z = det.floats.take(drows, axis=1)
        self.state[MEASURED][:, rows] = z[MEASURED]
        self.state[COV][:, rows] = self._p0
        self.meta[META_RADAR_ID:][:, rows] = det.ints[_DET_META].take(drows, axis=1)
        self.resumed += len(rows)

    def _update(self, rows: I, det: Detections, drows: I) -> None:
        """Kalman update of tracks `rows` with detections `drows`, after `associate`,
        whose S^-1 it reuses: x' = z - R S^-1 e, P' = R S^-1 P on each axis's block."""
        if len(rows) == 0:
            return
        z = det.floats.take(drows, axis=1)       # the new [x, y, vx, vy, rcs]
        old = self.state.take(rows, axis=1)
        inv_pp, inv_pv, inv_vv = self._s_inv.take(rows, axis=2)
        e = z[STATE] - old[STATE]
        dp, dv = e[POS], e[VEL]
        var_p, cov_pv, var_v = old[VAR_P], old[COV_PV], old[VAR_V]
        r_p, r_v = self._r_p, self._r_v
        new = np.empty_like(old)
        new[POS] = z[POS] - r_p * (inv_pp * dp + inv_pv * dv)
        new[VEL] = z[VEL] - r_v * (inv_pv * dp + inv_vv * dv)
        new[TRACK_RCS] = z[RCS]
        new[VAR_P] = r_p * (inv_pp * var_p + inv_pv * cov_pv)
        new[COV_PV] = r_p * (inv_pp * cov_pv + inv_pv * var_v)
        new[VAR_V] = r_v * (inv_pv * cov_pv + inv_vv * var_v)
        self.state[:, rows] = new
        self.meta[META_RADAR_ID:, rows] = det.ints[_DET_META].take(drows, axis=1)

    def _count(self, rows: I) -> None:
        """Hits and misses after an update of `rows`; confirmation; deletion."""
        meta = self.meta
        n = meta.shape[1]
        hits, misses = meta[HITS], meta[MISSES]      # views: updated in place
        hits += 1
        misses += 1
        misses[rows] = 0
        if len(rows) < n:
            hits *= misses == 0          # consecutive: a miss starts again from 0
        meta[CONFIRMED] |= hits >= self.s.confirm_hits
        if len(rows) == n:
            return                       # nobody missed: nobody is deleted
        keep = misses < self._miss_limits.take(meta[CONFIRMED])
        if np.count_nonzero(keep) < n:
            self.state = self.state.compress(keep, axis=1)
            self.meta = meta.compress(keep, axis=1)

    def _birth(self, det: Detections, drows: I | None) -> None:
        """A tentative track for each detection `drows` (None: every detection)."""
        fd = det.floats if drows is None else det.floats.take(drows, axis=1)
        di = det.ints[_DET_META] if drows is None else det.ints[_DET_META].take(drows, axis=1)
        k = fd.shape[1]
        new = np.empty((N_STATE, k))
        new[MEASURED] = fd
        new[COV] = self._p0
        meta = np.empty((N_META, k), dtype=np.int64)
        meta[:META_RADAR_ID] = self._meta_born
        meta[ID] = np.arange(self.next_id, self.next_id + k)
        meta[META_RADAR_ID:] = di
        self.next_id += k
        if len(self):
            new = np.concatenate([self.state, new], axis=1)
            meta = np.concatenate([self.meta, meta], axis=1)
        self.state, self.meta = new, meta

    def annotate_class(self, det: Detections) -> None:
        """Set the object class of the tracks updated or born this cycle from `det` (the
        cycle's detections, classes attached after the tracker ran), by radar ID."""
        if not len(self) or not len(det):
            return
        lut = _NO_CLASS_BY_ID.copy()
        lut[det.radar_id] = det.ints[OBJ_CLASS]
        meta = self.meta
        rid = meta[META_RADAR_ID]
        fresh = (meta[MISSES] == 0) & (rid >= 0)
        meta[META_OBJ_CLASS] = np.where(fresh, lut.take(rid, mode="clip"), meta[META_OBJ_CLASS])

    def tracks(self) -> list[RadarTrack]:
        """Every track, confirmed or not, as messages."""
        if not len(self):
            return []
        st = self.state
        r = np.hypot(st[X], st[Y])
        rr = (st[X] * st[VX] + st[Y] * st[VY]) / np.maximum(r, _TINY)
        x, y, vx, vy, rcs = st[MEASURED].tolist()
        x_var, y_var = st[VAR_P].tolist()
        m = self.meta.tolist()
        return list(starmap(RadarTrack, zip(
            m[ID], x, y, vx, vy, r.tolist(), rr.tolist(), rcs, map(bool, m[CONFIRMED]),
            m[HITS], m[MISSES], x_var, y_var, m[META_RADAR_ID], m[META_DYN_PROP],
            m[META_OBJ_CLASS], strict=True)))
