"""A cycle's detections: decoding a `RawCycle`, the prefilter and the centroid merge.
Pure and vectorised.

Detections are two matrices (floats and integers) with a row per attribute and a column
per detection. Radar frame: x forward, y left, origin at the radar; velocities are
relative to the radar.
"""

from collections import defaultdict
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from aeb_radar_camera.common.config.radar import MergeSettings, PrefilterSettings
from aeb_radar_camera.common.messages.radar import OutputMode
from aeb_radar_camera.services.radar.ars408.codec import decode_columns
from aeb_radar_camera.services.radar.ars408.table import BY_KIND, Kind, MessageSpec
from aeb_radar_camera.services.radar.assembly import ListRole, RawCycle
from aeb_radar_camera.services.radar.neighbours import pairs_within_self

F = npt.NDArray[np.float64]
I = npt.NDArray[np.int64]  # noqa: E741 (a column type, not a loop index)

UNKNOWN = -1
_NO_IDS = np.zeros(0, dtype=np.int64)
_ROW_BINS = np.arange(4, dtype=np.int64)

# Rows of Detections.floats and Detections.ints (columns of the (m, 5) views f and i).
X, Y, VX, VY, RCS = range(5)
RADAR_ID, DYN_PROP, OBJ_CLASS, PROB_OF_EXIST, INVALID_STATE = range(5)


@dataclass(frozen=True)
class Detections:
    """`floats` (5, m): rows x, y, vx, vy (m, m/s), rcs (dBsm). `ints` (5, m): rows radar
    ID, DynProp, object class (0x60D), ProbOfExist (0x60C), InvalidState (0x702); UNKNOWN
    (-1) when the radar did not send it.

    `f` and `i` are the (m, 5) views (a detection per row)."""

    floats: F
    ints: I

    @property
    def f(self) -> F:
        return self.floats.T

    @property
    def i(self) -> I:
        return self.ints.T

    @property
    def x(self) -> F:
        return self.floats[X]

    @property
    def y(self) -> F:
        return self.floats[Y]

    @property
    def vx(self) -> F:
        return self.floats[VX]

    @property
    def vy(self) -> F:
        return self.floats[VY]

    @property
    def rcs(self) -> F:
        return self.floats[RCS]

    @property
    def radar_id(self) -> I:
        return self.ints[RADAR_ID]

    def __len__(self) -> int:
        return int(self.floats.shape[1])

    def take(self, index: npt.NDArray[Any]) -> "Detections":
        """Detections selected by a boolean mask or an index array."""
        if index.dtype == np.bool_:
            return Detections(self.floats.compress(index, axis=1),
                              self.ints.compress(index, axis=1))
        return Detections(self.floats.take(index, axis=1), self.ints.take(index, axis=1))

    @staticmethod
    def empty() -> "Detections":
        return Detections(np.zeros((5, 0)), np.zeros((5, 0), dtype=np.int64))

    @staticmethod
    def of(x: Any, y: Any, vx: Any = 0.0, vy: Any = 0.0, rcs: Any = 10.0,
           radar_id: Any = UNKNOWN, dyn_prop: Any = UNKNOWN, obj_class: Any = UNKNOWN,
           prob_of_exist: Any = UNKNOWN, invalid_state: Any = UNKNOWN) -> "Detections":
        """Build from columns (scalars broadcast): for tests and simulators."""
        n = len(np.atleast_1d(x))
        f = np.empty((5, n))
        for k, v in enumerate((x, y, vx, vy, rcs)):
            f[k] = v
        i = np.empty((5, n), dtype=np.int64)
        for k, v in enumerate((radar_id, dyn_prop, obj_class, prob_of_exist, invalid_state)):
            i[k] = v
        return Detections(f, i)


# An empty cycle's detections (nothing ahead: every cycle of an empty road), shared:
# arrays with no column cannot be changed in place.
_NO_DETECTIONS = Detections.empty()

_SPECS: dict[OutputMode, tuple[MessageSpec, MessageSpec, MessageSpec | None]] = {
    OutputMode.OBJECTS: (BY_KIND[Kind.OBJECT_GENERAL], BY_KIND[Kind.OBJECT_QUALITY],
                         BY_KIND[Kind.OBJECT_EXTENDED]),
    OutputMode.CLUSTERS: (BY_KIND[Kind.CLUSTER_GENERAL], BY_KIND[Kind.CLUSTER_QUALITY], None),
}


def _signal_index(spec: MessageSpec, *attrs: str) -> list[int]:
    fields = spec.record._fields
    return [fields.index(a) for a in attrs]


# General frames: the float rows x, y, vx, vy, rcs and the integer id, dyn_prop, at the
# same signal positions for objects (0x60B) and clusters (0x701).
_GENERAL_F = _signal_index(BY_KIND[Kind.OBJECT_GENERAL], "dist_long_m", "dist_lat_m",
                           "vrel_long_mps", "vrel_lat_mps", "rcs_dbsm")
_GENERAL_I = _signal_index(BY_KIND[Kind.OBJECT_GENERAL], "id", "dyn_prop")
assert (_signal_index(BY_KIND[Kind.CLUSTER_GENERAL], "dist_long_m", "dist_lat_m", "vrel_long_mps",
                      "vrel_lat_mps", "rcs_dbsm", "id", "dyn_prop") == _GENERAL_F + _GENERAL_I)
_GENERAL_F_ROWS = np.array(_GENERAL_F, dtype=np.intp)
_GENERAL_I_ROWS = np.array(_GENERAL_I, dtype=np.intp)
# Every list message carries the radar's ID as its first signal.
assert all(spec.signals[0].attr == "id" for specs in _SPECS.values() for spec in specs if spec)


def _present(frames: list[bytes | None]) -> list[bytes]:
    return [d for d in frames if d is not None]


def occurrence_keys(ids: I) -> I:
    """`id + 256 * k` for the k-th frame carrying `id` in this cycle: a key that stays
    unique when IDs repeat (a cluster cycle of more than 256 clusters wraps the 8-bit ID),
    and pairs the k-th quality frame of an ID with the k-th general frame of that ID."""
    if len(ids) == 0 or (len(ids) <= 256 and int(np.bincount(ids).max()) == 1):
        return ids
    order = np.argsort(ids, kind="stable")
    ordered = ids[order]
    occurrence = np.empty_like(ids)
    occurrence[order] = np.arange(len(ids)) - np.searchsorted(ordered, ordered)
    return ids + 256 * occurrence


def _attach(
    spec: MessageSpec, frames: list[bytes | None], general_ids: I, keys: I,
    rows_of_keys: I | None, target: I, column: str, rejected: dict[str, int],
) -> None:
    """Copy signal `column` of quality / extended frames into the integer row `target`.

    The radar sends them in the order of the general frames: then it is one copy.
    Otherwise they are matched by ID key; `rows_of_keys` maps the general frames' keys
    to detection rows (-2 for a rejected general frame, whose quality frame is then
    dropped without a count; None when every general frame is a row, in order)."""
    datas = _present(frames)
    if not datas:
        return
    cols = decode_columns(spec, datas)
    for reason, n in cols.rejected.items():
        rejected[reason] = rejected.get(reason, 0) + n
    ids = cols.raw[0]
    values = cols.raw[_signal_index(spec, column)[0]]
    # The same IDs in the same order (both int64 rows): one copy.
    if (rows_of_keys is None and cols.all_valid and len(ids) == len(general_ids)
            and ids.tobytes() == general_ids.tobytes()):
        target[:] = values
        return
    qkeys = occurrence_keys(ids)[cols.valid]
    lut = np.full(int(max(keys.max(initial=0), qkeys.max(initial=0))) + 1, -1, dtype=np.int64)
    lut[keys] = np.arange(len(keys)) if rows_of_keys is None else rows_of_keys
    rows = lut[qkeys]
    unmatched = int(np.count_nonzero(rows == -1))
    if unmatched:
        rejected[f"unmatched_id:{spec.dbc_name}"] = unmatched
    ok = rows >= 0
    target[rows[ok]] = values[cols.valid][ok]


@dataclass
class GeneralFrames:
    """The general frames of a cycle decoded: the detections, and what matching the
    quality / extended frames to them needs. `rejected` counts frames by reason."""

    det: Detections
    ids: I                      # radar IDs of the general frames as sent
    keys: I                     # their occurrence keys
    rows: I | None              # detection row of each general frame (-2 rejected);
                                # None when every frame is a row, in order
    rejected: dict[str, int]


def decode_general(cycle: RawCycle) -> GeneralFrames:
    """The cycle's general frames (0x60B / 0x701) as detections.

    Object IDs are unique within a cycle: a repeated one is a fault (the first frame
    wins). Cluster IDs may repeat (more than 256 clusters): each frame is kept.
    """
    rejected: dict[str, int] = {}
    general_spec = _SPECS[cycle.mode][0]
    datas = _present(cycle.general)
    if not datas:
        return GeneralFrames(_NO_DETECTIONS, _NO_IDS, _NO_IDS, None, rejected)
    cols = decode_columns(general_spec, datas)
    rejected.update(cols.rejected)
    ids = cols.raw[0]
    keys = occurrence_keys(ids)
    keep: npt.NDArray[np.bool_] | None = None if cols.all_valid else cols.valid
    if cycle.mode is OutputMode.OBJECTS and keys is not ids:
        unique = keys < 256
        dupes = int(np.count_nonzero(cols.valid & ~unique))
        if dupes:
            rejected[f"duplicate_id:{general_spec.dbc_name}"] = dupes
        keep = cols.valid & unique
    f = cols.phys.take(_GENERAL_F_ROWS, axis=0)
    i = np.empty((5, len(ids)), dtype=np.int64)
    i[RADAR_ID:DYN_PROP + 1] = cols.raw.take(_GENERAL_I_ROWS, axis=0)
    i[DYN_PROP + 1:] = UNKNOWN          # not sent yet: quality and extended frames
    rows: I | None = None
    if keep is not None:
        f, i = f.compress(keep, axis=1), i.compress(keep, axis=1)
        rows = np.full(len(keys), -2, dtype=np.int64)
        rows[keep] = np.arange(f.shape[1])
    return GeneralFrames(Detections(f, i), ids, keys, rows, rejected)


def attach_extras(cycle: RawCycle, g: GeneralFrames, quality: bool = True) -> None:
    """Decode the cycle's quality / extended frames into the detections' ProbOfExist,
    class (objects) or InvalidState (clusters) rows; rejections go to `g.rejected`.
    `quality` False: the quality list was attached already (attach_list)."""
    if quality:
        attach_list(cycle, g, ListRole.QUALITY)
    if cycle.mode is OutputMode.OBJECTS:
        attach_list(cycle, g, ListRole.EXTENDED)


def attach_list(cycle: RawCycle, g: GeneralFrames, role: int) -> None:
    """Decode one of the cycle's extra lists (ListRole.QUALITY, or EXTENDED for
    objects) into its detection row; rejections go to `g.rejected`. A list can be
    attached as soon as all its frames are in, before the cycle's other frames."""
    if not len(g.det):
        return
    _, quality_spec, extended_spec = _SPECS[cycle.mode]
    i = g.det.ints
    if role == ListRole.EXTENDED:
        assert extended_spec is not None and cycle.mode is OutputMode.OBJECTS
        _attach(extended_spec, cycle.extended, g.ids, g.keys, g.rows, i[OBJ_CLASS],
                "obj_class", g.rejected)
    elif cycle.mode is OutputMode.OBJECTS:
        _attach(quality_spec, cycle.quality, g.ids, g.keys, g.rows, i[PROB_OF_EXIST],
                "prob_of_exist", g.rejected)
    else:
        _attach(quality_spec, cycle.quality, g.ids, g.keys, g.rows, i[INVALID_STATE],
                "invalid_state", g.rejected)


def decode_cycle(cycle: RawCycle) -> tuple[Detections, dict[str, int]]:
    """The cycle's detections with every attribute, and the number of frames rejected by
    reason (``out_of_range:<signal>``, ``duplicate_id:<message>``,
    ``unmatched_id:<message>``)."""
    g = decode_general(cycle)
    attach_extras(cycle, g)
    return g.det, g.rejected


def prefilter(det: Detections, s: PrefilterSettings) -> Detections:
    """Paper's prefilter: forward only, min < range <= max, RCS above the threshold; plus
    the optional existence-probability and cluster-validity filters."""
    if not len(det):
        return det
    fl = det.floats
    x, y = fl[X], fl[Y]
    r2 = x * x + y * y
    keep = (r2 > s.min_range_m**2) & (r2 <= s.max_range_m**2) & (fl[RCS] > s.min_rcs_dbsm)
    if s.forward_only:
        keep &= x > 0
    if s.min_prob_of_exist > 0:
        # Unknown (no quality frames) passes: the filter cannot judge it.
        p = det.ints[PROB_OF_EXIST]
        keep &= (p == UNKNOWN) | (p >= s.min_prob_of_exist)
    if s.drop_cluster_invalid_states:
        keep &= ~np.isin(det.ints[INVALID_STATE], np.asarray(s.drop_cluster_invalid_states))
    return det if np.count_nonzero(keep) == len(keep) else det.take(keep)


def merge(det: Detections, s: MergeSettings) -> Detections:
    """Centroid merge: the strongest unmerged detection seeds a group of every unmerged
    detection within `distance_m` whose velocity differs by at most `velocity_mps`; the
    group becomes one detection at the mean position and velocity, with the seed's RCS,
    radar ID and attributes. When anything merges, the result is ordered by RCS
    (strongest first, ties in input order); otherwise it is the input.

    Seeds, not chains: a chain of returns along a guard rail does not collapse into one
    phantom point between its ends; a group spans at most 2 * distance_m.
    """
    n = len(det)
    if not s.enabled or n < 2:
        return det
    fl = det.floats
    ii, jj = pairs_within_self(fl[X], fl[Y], s.distance_m)
    if len(ii) == 0:
        return det
    vx, vy = fl[VX], fl[VY]
    dvx = vx.take(ii) - vx.take(jj)
    dvy = vy.take(ii) - vy.take(jj)
    similar = dvx * dvx + dvy * dvy <= s.velocity_mps**2
    if not np.count_nonzero(similar):
        return det
    # The seed walk is sequential (a seed takes its mates before the next seed looks),
    # over the few similar pairs.
    neighbours: defaultdict[int, list[int]] = defaultdict(list)
    for i, j in zip(ii.compress(similar).tolist(), jj.compress(similar).tolist(), strict=True):
        neighbours[i].append(j)
        neighbours[j].append(i)
    adjacent = neighbours.get
    taken = [False] * n
    seeds: list[int] = []
    groups: list[list[int]] = []          # groups of two or more: [seed, members...]
    positions: list[int] = []             # their seed's position in `seeds`
    for i in np.argsort(-fl[RCS], kind="stable").tolist():
        if taken[i]:
            continue
        taken[i] = True
        mates = [j for j in adjacent(i, ()) if not taken[j]]
        if mates:
            for j in mates:
                taken[j] = True
            groups.append([i, *mates])
            positions.append(len(seeds))
        seeds.append(i)
    out = det.take(np.asarray(seeds, dtype=np.int64))
    # Each group's mean: one weighted bincount over the four rows of its members (row r
    # of group g at bin r * G + g).
    members = [j for g in groups for j in g]
    group_of = np.repeat(np.arange(len(groups)), [len(g) for g in groups])
    bins = (group_of + _ROW_BINS[:, None] * len(groups)).ravel()
    sums = np.bincount(bins, weights=np.take(fl[X:VY + 1], members, axis=1).ravel(),
                       minlength=4 * len(groups)).reshape(4, len(groups))
    out.floats[X:VY + 1, positions] = sums / np.bincount(group_of)
    return out
