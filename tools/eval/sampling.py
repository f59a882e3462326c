"""Stratified sampling of ROIs for labelling, as the paper drew its 320 frames: across
edge-density bands and operating conditions, so that a few strata (most ROIs of a drive
are easy) do not fill the label set.

Every ROI falls into one stratum: its density band (the paper's gate score, bands split
at `edges`) crossed with the chosen condition keys (lighting, session group, kind,
camera). The sample takes the same number from every stratum; a stratum with too few
ROIs gives all it has and the rest is shared among the others.
"""

import fnmatch
from collections.abc import Callable, Sequence

import numpy as np

from aeb_radar_camera.tools.eval.records import RoiRecord

DENSITY_EDGES = (0.025, 0.05, 0.1)
KEYS = ("lighting", "group", "kind", "camera", "session")


def density_band(d: float, edges: Sequence[float] = DENSITY_EDGES) -> str:
    lo = 0.0
    for e in edges:
        if d < e:
            return f"{lo:g}-{e:g}"
        lo = e
    return f">={lo:g}"


def stratum_key(keys: Sequence[str], groups: Sequence[tuple[str, str]],
                edges: Sequence[float]) -> Callable[[RoiRecord], tuple[str, ...]]:
    """The stratum of a record. Raises ValueError for an unknown key."""
    unknown = [k for k in keys if k not in KEYS]
    if unknown:
        raise ValueError(f"unknown strata {unknown}; choose from {', '.join(KEYS)}")

    def group_of(r: RoiRecord) -> str:
        return next((name for name, pat in groups if fnmatch.fnmatchcase(r.session, pat)),
                    "other")

    def key(r: RoiRecord) -> tuple[str, ...]:
        out = [density_band(r.density, edges)]
        for k in keys:
            out.append(group_of(r) if k == "group" else str(getattr(r, k)))
        return tuple(out)

    return key


def stratified(records: Sequence[RoiRecord], n: int, key: Callable[[RoiRecord], tuple],
               seed: int = 0) -> list[RoiRecord]:
    """`n` records (all when fewer), equal shares per stratum, in random order."""
    rng = np.random.default_rng(seed)
    strata: dict[tuple, list[RoiRecord]] = {}
    for r in records:
        strata.setdefault(key(r), []).append(r)
    pools = []
    for name in sorted(strata):
        members = strata[name]
        order = rng.permutation(len(members))
        pools.append([members[i] for i in order])
    picked: list[RoiRecord] = []
    depth = 0
    while len(picked) < n and any(depth < len(p) for p in pools):
        for p in pools:
            if depth < len(p) and len(picked) < n:
                picked.append(p[depth])
        depth += 1
    order = rng.permutation(len(picked))
    return [picked[i] for i in order]
