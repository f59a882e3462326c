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
so the 4x4 covariance is two 2x2 blocks [[var_p, cov_pv], [cov_pv, var_v]], one per axis.
They are stored as (n, 2) arrays (column 0 the x axis, column 1 the y axis) and every
step is a closed-form elementwise formula: no batched 4x4 inverses (numpy calls cost
microseconds each on a small CPU, whatever their size).
"""

import numpy as np
import numpy.typing as npt

from common.config.radar import TrackerSettings
from common.messages.radar import RadarTrack
from services.radar.detections import DYN_PROP, OBJ_CLASS, RADAR_ID, RCS, VY, Detections
from services.radar.neighbours import pairs_within

F = npt.NDArray[np.float64]
I = npt.NDArray[np.int64]  # noqa: E741
B = npt.NDArray[np.bool_]

_EMPTY = np.zeros(0, dtype=np.int64)

# Columns of KalmanTracker.cov: per axis (x, y) the 2x2 block [[var_p, cov_pv], [cov_pv, var_v]].
VAR_P = slice(0, 2)
COV_PV = slice(2, 4)
VAR_V = slice(4, 6)
# Columns of KalmanTracker.meta.
ID, HITS, MISSES, CONFIRMED, META_RADAR_ID, META_DYN_PROP, META_OBJ_CLASS = range(7)


def covariance_step(dt: float, accel_std: float) -> tuple[F, F]:
    """(M, q) with cov' = cov @ M + q: the covariance prediction F P F^T + Q written
    on the per-axis blocks, Q from piecewise-constant white acceleration."""
    m = np.eye(6)
    for axis in range(2):
        p, c, v = axis, 2 + axis, 4 + axis
        m[c, p] = 2 * dt          # var_p' = var_p + 2 dt cov + dt^2 var_v
        m[v, p] = dt * dt
        m[v, c] = dt              # cov' = cov + dt var_v
    q = accel_std**2
    noise = np.array([q * dt**4 / 4] * 2 + [q * dt**3 / 2] * 2 + [q * dt * dt] * 2)
    return m, noise


class KalmanTracker:
    """State: `x` (n, 4) [x, y, vx, vy]; `cov` (n, 6) the per-axis covariance blocks;
    `rcs` (n,); `meta` (n, 7) track ID, consecutive hits, consecutive misses, confirmed,
    and the last detection's radar ID, DynProp and class."""

    def __init__(self, settings: TrackerSettings) -> None:
        self.s = settings
        self.r_pos = np.array([settings.pos_x_std_m**2, settings.pos_y_std_m**2])
        self.r_vel = np.array([settings.vel_x_std_mps**2, settings.vel_y_std_mps**2])
        self._cov0 = np.concatenate([self.r_pos, [0.0, 0.0], self.r_vel])
        self.next_id = 1
        self.last_t: float | None = None
        self.resets = 0
        self._step_cache: tuple[float, F, F] | None = None
        self._clear()

    def _clear(self) -> None:
        self.x: F = np.zeros((0, 4))
        self.cov: F = np.zeros((0, 6))
        self.rcs: F = np.zeros(0)
        self.meta: I = np.zeros((0, 7), dtype=np.int64)

    def __len__(self) -> int:
        return len(self.x)

    @property
    def ids(self) -> I:
        return self.meta[:, ID]

    @property
    def confirmed(self) -> B:
        return self.meta[:, CONFIRMED].astype(np.bool_)

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
        cached = self._step_cache
        if cached is None or cached[0] != dt:
            cached = self._step_cache = (dt, *covariance_step(dt, self.s.accel_std_mps2))
        self.x[:, 0:2] += dt * self.x[:, 2:4]
        self.cov = self.cov @ cached[1] + cached[2]

    def associate(self, det: Detections) -> tuple[I, I]:
        """(track rows, detection rows) matched, by greedy nearest neighbour on the gated
        Mahalanobis cost."""
        # Euclidean pre-gate on position first, the Mahalanobis distance only for the
        # candidate pairs.
        ti, di = pairs_within(self.x[:, 0], self.x[:, 1], det.x, det.y,
                              self.s.gate_max_distance_m)
        if len(ti) == 0:
            return _EMPTY, _EMPTY
        d = det.f[di, 0:VY + 1] - self.x[ti]
        dp, dv = d[:, 0:2], d[:, 2:4]
        c = self.cov[ti]
        a = c[:, VAR_P] + self.r_pos              # innovation covariance S = P + R, per axis
        b = c[:, COV_PV]
        v = c[:, VAR_V] + self.r_vel
        d2 = ((dp * dp * v - 2 * dp * dv * b + dv * dv * a) / (a * v - b * b)).sum(axis=1)
        gated = d2 <= self.s.gate_chi2
        ti, di, cost = ti[gated], di[gated], d2[gated]
        if self.s.radar_id_bonus > 0:
            rid = det.i[di, RADAR_ID]
            same = (self.meta[ti, META_RADAR_ID] == rid) & (rid >= 0)
            cost = cost - self.s.radar_id_bonus * same
        order = np.argsort(cost, kind="stable")
        used_t: set[int] = set()
        used_d: set[int] = set()
        mt: list[int] = []
        md: list[int] = []
        for t, dd in zip(ti[order].tolist(), di[order].tolist(), strict=True):
            if t in used_t or dd in used_d:
                continue
            used_t.add(t)
            used_d.add(dd)
            mt.append(t)
            md.append(dd)
        return np.asarray(mt, dtype=np.int64), np.asarray(md, dtype=np.int64)

    def _update(self, rows: I, det: Detections, drows: I) -> None:
        if len(rows) == 0:
            return
        c = self.cov[rows]
        pa, pb, pc = c[:, VAR_P], c[:, COV_PV], c[:, VAR_V]
        a, v = pa + self.r_pos, pc + self.r_vel      # S = P + R
        inv_det = 1.0 / (a * v - pb * pb)
        pb2 = pb * pb
        # K = P S^-1, closed form per axis.
        k11 = (pa * v - pb2) * inv_det
        k12 = (pb * a - pa * pb) * inv_det
        k21 = (pb * v - pc * pb) * inv_det
        k22 = (pc * a - pb2) * inv_det
        d = det.f[drows, 0:VY + 1] - self.x[rows]
        dp, dv = d[:, 0:2], d[:, 2:4]
        self.x[rows] += np.concatenate([k11 * dp + k12 * dv, k21 * dp + k22 * dv], axis=1)
        # P' = (I - K) P; the block stores cov_pv once, which keeps it symmetric.
        self.cov[rows] = np.concatenate(
            [(1 - k11) * pa - k12 * pb, (1 - k11) * pb - k12 * pc, (1 - k22) * pc - k21 * pb],
            axis=1)
        self.rcs[rows] = det.f[drows, RCS]
        self.meta[rows, META_RADAR_ID:] = det.i[drows][:, [RADAR_ID, DYN_PROP, OBJ_CLASS]]

    def _birth(self, det: Detections, drows: I) -> None:
        k = len(drows)
        if k == 0:
            return
        meta = np.zeros((k, 7), dtype=np.int64)
        meta[:, ID] = np.arange(self.next_id, self.next_id + k)
        meta[:, HITS] = 1
        meta[:, CONFIRMED] = self.s.confirm_hits <= 1
        meta[:, META_RADAR_ID:] = det.i[drows][:, [RADAR_ID, DYN_PROP, OBJ_CLASS]]
        self.next_id += k
        self.x = np.concatenate([self.x, det.f[drows, 0:VY + 1]])
        self.cov = np.concatenate([self.cov, np.broadcast_to(self._cov0, (k, 6))])
        self.rcs = np.concatenate([self.rcs, det.f[drows, RCS]])
        self.meta = np.concatenate([self.meta, meta])

    def step(self, det: Detections, t_s: float) -> None:
        """Advance to time `t_s` (seconds, the cycle's source clock) with this cycle's
        detections."""
        self.predict(self._dt(t_s))
        rows, drows = self.associate(det)
        matched = np.zeros(len(self), dtype=np.bool_)
        matched[rows] = True
        self._update(rows, det, drows)
        meta = self.meta
        meta[:, HITS] = np.where(matched, meta[:, HITS] + 1, 0)
        meta[:, MISSES] = np.where(matched, 0, meta[:, MISSES] + 1)
        confirmed = (meta[:, CONFIRMED] > 0) | (meta[:, HITS] >= self.s.confirm_hits)
        meta[:, CONFIRMED] = confirmed
        limit = np.where(confirmed, self.s.delete_after_misses,
                         self.s.delete_tentative_after_misses)
        keep = meta[:, MISSES] < limit
        if not keep.all():
            self.x, self.cov, self.rcs, self.meta = (
                self.x[keep], self.cov[keep], self.rcs[keep], meta[keep])
        unmatched = np.ones(len(det), dtype=np.bool_)
        unmatched[drows] = False
        self._birth(det, np.flatnonzero(unmatched))

    def annotate_class(self, det: Detections) -> None:
        """Set the object class of the tracks updated or born this cycle from `det` (the
        cycle's detections, classes attached after the tracker ran), by radar ID."""
        if not len(self) or not len(det):
            return
        lut = np.full(256, -1, dtype=np.int64)
        lut[det.radar_id] = det.i[:, OBJ_CLASS]
        meta = self.meta
        fresh = (meta[:, MISSES] == 0) & (meta[:, META_RADAR_ID] >= 0)
        meta[fresh, META_OBJ_CLASS] = lut[meta[fresh, META_RADAR_ID]]

    def tracks(self) -> list[RadarTrack]:
        """Every track, confirmed or not, as messages."""
        if not len(self):
            return []
        x, y, vx, vy = self.x.T
        r = np.hypot(x, y)
        rr = np.divide(x * vx + y * vy, r, out=np.zeros_like(r), where=r > 0)
        m = self.meta.T.tolist()
        # One tolist() per column: per-element float() conversions would dominate.
        columns = zip(
            m[ID], x.tolist(), y.tolist(), vx.tolist(), vy.tolist(), r.tolist(),
            rr.tolist(), self.rcs.tolist(), [c > 0 for c in m[CONFIRMED]], m[HITS],
            m[MISSES], self.cov[:, 0].tolist(), self.cov[:, 1].tolist(),
            m[META_RADAR_ID], m[META_DYN_PROP], m[META_OBJ_CLASS],
            strict=True,
        )
        return [RadarTrack(*c) for c in columns]
