"""The radar pipeline's previous merge and tracker, kept verbatim as the benchmark's
baseline (`bench_radar` runs it beside the current code in the same run) and as the
oracle of the tests that check the current code gives the same tracks.

This is the code as it was before the tracker, merge and decoded detections were laid
out as contiguous rows per quantity (commit e29bc93): detections one row per detection,
per-pair gathers of strided columns, a 3 m window search before the gate, the greedy
loop over every gated pair, the merge's dense membership matrix. The near-pair searches
are the current ones (`services.radar.neighbours`: the same sorted-window algorithm, now
also keeping pairs exactly on the radius). Not used by the service.
"""

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from common.config.radar import MergeSettings, RadarSettings, SensorSettings, TrackerSettings
from common.messages.radar import RadarTrack
from services.radar.core import RadarCore
from services.radar.detections import (
    DYN_PROP,
    OBJ_CLASS,
    RADAR_ID,
    RCS,
    VX,
    VY,
    Detections,
    X,
)
from services.radar.neighbours import pairs_within, pairs_within_self

F = npt.NDArray[np.float64]
I = npt.NDArray[np.int64]  # noqa: E741
B = npt.NDArray[np.bool_]

_EMPTY = np.zeros(0, dtype=np.int64)


@dataclass(frozen=True)
class RowDetections:
    """The previous layout: `f` (m, 5) x, y, vx, vy, rcs and `i` (m, 5) radar ID, DynProp,
    class, ProbOfExist, InvalidState, one row per detection."""

    f: F
    i: I

    @property
    def x(self) -> F:
        return self.f[:, X]

    @property
    def y(self) -> F:
        return self.f[:, 1]

    @property
    def rcs(self) -> F:
        return self.f[:, RCS]

    @property
    def radar_id(self) -> I:
        return self.i[:, RADAR_ID]

    def __len__(self) -> int:
        return len(self.f)

    @staticmethod
    def empty() -> "RowDetections":
        return RowDetections(np.zeros((0, 5)), np.zeros((0, 5), dtype=np.int64))

    @staticmethod
    def of(det: Detections) -> "RowDetections":
        return RowDetections(np.ascontiguousarray(det.f), np.ascontiguousarray(det.i))


def reference_merge(det: "RowDetections", s: MergeSettings) -> "RowDetections":
    """Centroid merge: the strongest unmerged detection seeds a group of every unmerged
    detection within `distance_m` whose velocity differs by at most `velocity_mps`; the
    group becomes one detection at the mean position and velocity, with the seed's RCS,
    radar ID and attributes.

    Seeds, not chains: a chain of returns along a guard rail does not collapse into one
    phantom point between its ends; a group spans at most 2 * distance_m.
    """
    n = len(det)
    if not s.enabled or n < 2:
        return det
    ii, jj = pairs_within_self(det.x, det.y, s.distance_m)
    dv = det.f[ii, VX:VY + 1] - det.f[jj, VX:VY + 1]
    similar = (dv * dv).sum(axis=1) <= s.velocity_mps**2
    if not similar.any():
        return det
    # Sparse neighbour lists in plain Python: numpy per-row calls would cost more than
    # the few pairs a scene has.
    neighbours: dict[int, list[int]] = {}
    for i, j in zip(ii[similar].tolist(), jj[similar].tolist(), strict=True):
        neighbours.setdefault(i, []).append(j)
        neighbours.setdefault(j, []).append(i)
    group = [-1] * n
    seeds: list[int] = []
    for i in np.argsort(-det.rcs, kind="stable").tolist():
        if group[i] >= 0:
            continue
        g = len(seeds)
        seeds.append(i)
        group[i] = g
        for j in neighbours.get(i, ()):
            if group[j] < 0:
                group[j] = g
    k = len(seeds)
    member = np.zeros((k, n))
    member[group, np.arange(n)] = 1.0
    seed = np.asarray(seeds, dtype=np.int64)
    f = det.f[seed]
    f[:, X:VY + 1] = (member @ det.f[:, X:VY + 1]) / member.sum(axis=1)[:, None]
    return RowDetections(f, det.i[seed])


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


class ReferenceTracker:
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

    def associate(self, det: RowDetections) -> tuple[I, I]:
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

    def _update(self, rows: I, det: RowDetections, drows: I) -> None:
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

    def _birth(self, det: RowDetections, drows: I) -> None:
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

    def step(self, det: RowDetections, t_s: float) -> None:
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

    def annotate_class(self, det: Detections | RowDetections) -> None:
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


class ReferenceCore(RadarCore):
    """A radar core whose merge and tracker are the previous ones (decode, prefilter,
    cycle assembly and messages are the current code)."""

    def __init__(self, sensor: SensorSettings, settings: RadarSettings) -> None:
        super().__init__(sensor, settings)
        self.tracker = ReferenceTracker(settings.tracker)  # type: ignore[assignment]

    def _merge_and_step(self, kept: Detections, t_s: float) -> None:
        self.tracker.step(reference_merge(RowDetections.of(kept), self.settings.merge),  # type: ignore[arg-type]
                          t_s)
