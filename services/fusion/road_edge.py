"""The road's edge from stationary radar returns (pure, no I/O, no clocks).

Before a bend the ego drives straight (yaw rate 0) and its predicted path runs straight
on; a guard rail or a row of posts along the bend's outside edge crosses that line a
few tens of metres ahead, and the camera rightly confirms that something stands there.
What tells the rail from an obstacle is its shape: the returns of a road's edge form a
smooth line that starts beside the ego, runs along the road and bends no tighter than a
road the ego could take at its speed. A track that lies on such a chain, with more of
the chain beyond it, is the road's edge, not an obstacle in the path.

Recall first: a stopped car beyond the end of a straight rail, or beside it in the lane,
must stay in the path. The chain therefore
- starts beside the path (|offset| beyond the path's half width, margin included) within
  `start_range_m`, running along the path there (`start_heading_deg`);
- grows one member at a time, each within `max_spacing_m` of the last, where the local
  fit of the members behind it (a quadratic in arc length, over `fit_length_m`) keeps every
  residual within `residual_m` and the road's curvature (the path's plus the chain's own)
  within what a driver takes at the ego's speed (`max_lateral_mps2`) and within the
  path's `max_curvature_per_m`;
- takes a track out of the path only if the chain has at least `min_members` and at least
  `members_after` further members beyond it: the chain's end (where a car behind the
  rail's end would be) is never the edge.
"""

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.polynomial import polynomial as P

from aeb_radar_camera.common.config.fusion import RoadEdgeSettings

# The ego's speed below this counts as this for the curvature bound (m/s): at a crawl
# any bend is drivable and the path's own curvature cap bounds it.
_MIN_SPEED_MPS = 1.0
# Two returns closer than this along the path are one place on the edge (m): the next
# member must lie beyond the last (a car's several returns on its rear face are no line).
_MIN_STEP_M = 1.0


@dataclass(frozen=True, slots=True)
class EdgePoint:
    """A stationary track in the predicted path's coordinates."""

    track_id: int
    s_m: float       # arc length along the path
    d_m: float       # offset from it, left positive


@dataclass(frozen=True, slots=True)
class RoadEdge:
    """A chain of stationary returns that forms a road's edge, nearest first, and the
    largest |road curvature| (1/m, signed) its fits implied."""

    members: tuple[EdgePoint, ...]
    curvature_per_m: float


def quadratic_fit(points: Sequence[tuple[float, float]]) -> tuple[float, float, float]:
    """Least squares d = c0 + c1 s + c2 s^2 through (s, d) points: (c0, c1, c2). Two
    points give a line (c2 = 0), one (or all at one s) a constant. Raises ValueError for
    no point."""
    if not points:
        raise ValueError("no point to fit")
    xs, ys = np.array(points, dtype=float).T
    return _fit(xs, ys, min(2, len(points) - 1))


def bounded_fit(points: Sequence[tuple[float, float]], c2_lo: float, c2_hi: float
                ) -> tuple[float, float, float]:
    """The least squares quadratic d = c0 + c1 s + c2 s^2 with c2 within [c2_lo, c2_hi]:
    the unconstrained fit where its c2 lies there, else c2 at the nearer bound and the line
    fitted to what is left (the problem is convex in c2). Raises ValueError for no
    point."""
    c0, c1, c2 = quadratic_fit(points)
    if c2_lo <= c2 <= c2_hi or len(points) < 3:
        return c0, c1, c2
    c2 = min(max(c2, c2_lo), c2_hi)
    xs, ys = np.array(points, dtype=float).T
    b0, b1, _ = _fit(xs, ys - c2 * xs * xs, 1)
    return b0, b1, c2


def _fit(xs: np.ndarray, ys: np.ndarray, degree: int) -> tuple[float, float, float]:
    """numpy's least squares polynomial (its columns scaled: well conditioned 60 m ahead)
    as (c0, c1, c2); a constant where every s is the same."""
    if np.ptp(xs) < 1e-6:
        degree = 0
    c = np.pad(P.polyfit(xs, ys, degree), (0, 2 - degree))
    return float(c[0]), float(c[1]), float(c[2])


def curvature_limit(speed_mps: float, s: RoadEdgeSettings, max_curvature_per_m: float
                    ) -> float:
    """The tightest road curvature (1/m) a driver takes at `speed_mps`: lateral
    acceleration `max_lateral_mps2`, and never beyond the path's own cap."""
    v = max(abs(speed_mps), _MIN_SPEED_MPS)
    return min(s.max_lateral_mps2 / (v * v), max_curvature_per_m)


class _Chain:
    def __init__(self, seed: EdgePoint) -> None:
        self.members = [seed]
        self.curvature = 0.0


def _admits(chain: _Chain, p: EdgePoint, s: RoadEdgeSettings, path_curvature: float,
            limit: float) -> float | None:
    """The road curvature the chain implies with `p` as its next member, or None when
    `p` does not continue it smoothly."""
    last = chain.members[-1]
    if p.s_m < last.s_m + _MIN_STEP_M:
        return None
    if math.hypot(p.s_m - last.s_m, p.d_m - last.d_m) > s.max_spacing_m:
        return None
    local = [m for m in chain.members if m.s_m >= p.s_m - s.fit_length_m]
    if len(local) < 2:
        local = chain.members[-2:]
    pts = [(m.s_m, m.d_m) for m in local] + [(p.s_m, p.d_m)]
    if len(pts) == 2:
        # The chain's first step: the edge runs along the ego's path where it starts.
        slope = (pts[1][1] - pts[0][1]) / (pts[1][0] - pts[0][0])
        return path_curvature if abs(slope) <= math.tan(math.radians(
            s.start_heading_deg)) else None
    # The points must lie within residual_m of a curve whose road curvature (the path's
    # plus the chain's own, 2 c2: at least the true one's for a chain at an angle, so the
    # bound is the stricter there) a driver takes at this speed. The bound is on the
    # curve, so radar noise on three close returns does not read as a bend too tight.
    c0, c1, c2 = bounded_fit(pts, (-limit - path_curvature) / 2.0,
                             (limit - path_curvature) / 2.0)
    if any(abs(c0 + c1 * x + c2 * x * x - y) > s.residual_m for x, y in pts):
        return None
    return path_curvature + 2.0 * c2


def road_edges(points: Sequence[EdgePoint], half_width_m: float, path_curvature: float,
               speed_mps: float, s: RoadEdgeSettings, max_curvature_per_m: float
               ) -> list[RoadEdge]:
    """The chains among this cycle's stationary tracks (`points`, in path coordinates)
    that form a road's edge: on each side of the path, from the nearest track beside it
    within `start_range_m`, grown as the module says. Chains with fewer than
    `min_members` are none."""
    limit = curvature_limit(speed_mps, s, max_curvature_per_m)
    ahead = sorted((p for p in points if p.s_m >= 0.0), key=lambda p: p.s_m)
    edges: list[RoadEdge] = []
    for side in (1.0, -1.0):
        seeds = [p for p in ahead if side * p.d_m > half_width_m and p.s_m <= s.start_range_m]
        if not seeds:
            continue
        chain = _Chain(seeds[0])
        used = {seeds[0].track_id}
        while True:
            best: tuple[EdgePoint, float] | None = None
            for p in ahead:
                if p.track_id in used:
                    continue
                if p.s_m > chain.members[-1].s_m + s.max_spacing_m:
                    break
                k = _admits(chain, p, s, path_curvature, limit)
                if k is not None:
                    best = (p, k)
                    break
            if best is None:
                break
            chain.members.append(best[0])
            used.add(best[0].track_id)
            if abs(best[1]) > abs(chain.curvature):
                chain.curvature = best[1]
        if len(chain.members) >= s.min_members:
            edges.append(RoadEdge(tuple(chain.members), chain.curvature))
    return edges


def on_edge(edges: Sequence[RoadEdge], s: RoadEdgeSettings) -> dict[int, str]:
    """The tracks the chains show as the road's edge (every member with at least
    `members_after` members beyond it), by id, with the reason."""
    out: dict[int, str] = {}
    for e in edges:
        n = len(e.members)
        k = e.curvature_per_m
        bend = (f"R {1 / abs(k):.0f} m {'left' if k > 0 else 'right'}"
                if abs(k) > 1e-4 else "straight")
        for i, m in enumerate(e.members[:max(0, n - s.members_after)]):
            out[m.track_id] = (f"road edge: member {i + 1} of {n} stationary returns from "
                               f"s {e.members[0].s_m:.1f} m, offset "
                               f"{e.members[0].d_m:+.2f} m ({bend})")
    return out
