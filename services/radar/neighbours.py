"""Near pairs within one point set, and candidate pairs between two, without testing
every pair when there are many.

`pairs_within_self` (the merge's neighbours) sorts the points on x and looks at a window
per point; `candidates_in_boxes` (the tracker's gate) buckets points into strips along x
sorted by y, so that a box around a point is three runs of the sorted keys.
"""

from functools import lru_cache

import numpy as np
import numpy.typing as npt

F = npt.NDArray[np.float64]
I = npt.NDArray[np.int64]  # noqa: E741

# Up to this many points squared, testing every pair costs less than sorting first.
_DENSE_MAX = 4096
# Windows are widened by this much so that rounding in a window bound never loses a pair
# that the exact test keeps (quantised radar positions sit exactly on bounds).
_EPS = 1e-6
_STRIP_OFFSETS = np.array([[-1.0], [0.0], [1.0]])


def _empty() -> tuple[I, I]:
    return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)


def _expand(lo: I, counts: I, owner: I, total: int) -> tuple[I, I]:
    """Every (owner[k], p) with lo[k] <= p < lo[k] + counts[k] (`total` of them)."""
    i = np.repeat(owner, counts)
    first = np.repeat(lo - (np.cumsum(counts) - counts), counts)
    return i, first + np.arange(total)


@lru_cache(maxsize=64)
def _upper_triangle(n: int) -> npt.NDArray[np.bool_]:
    """(n, n) mask of i < j: each unordered pair once."""
    return np.triu(np.ones((n, n), dtype=np.bool_), k=1)


def pairs_within_self(x: F, y: F, radius: float) -> tuple[I, I]:
    """Index pairs (i, j) of one point set, each unordered pair once, whose distance is
    at most `radius`.

    Candidates come from a window on the points sorted by x, so the cost grows with the
    number of near pairs, not with n * n."""
    n = len(x)
    if n < 2:
        return _empty()
    if n * n <= _DENSE_MAX:
        dx = x[:, None] - x[None, :]
        dy = y[:, None] - y[None, :]
        i, j = ((dx * dx + dy * dy <= radius * radius) & _upper_triangle(n)).nonzero()
        return i, j
    order = np.argsort(x, kind="stable")
    xs, ys = x[order], y[order]
    counts = np.searchsorted(xs, xs + (radius + _EPS), "right") - np.arange(1, n + 1)
    total = int(counts.sum())
    if total == 0:
        return _empty()
    p, q = _expand(np.arange(1, n + 1), counts, np.arange(n), total)
    dx = xs[q] - xs[p]
    dy = ys[q] - ys[p]
    keep = dx * dx + dy * dy <= radius * radius
    return order[p[keep]], order[q[keep]]


def candidates_in_boxes(ax: F, ay: F, half_x: float, half_y: F | float, bx: F, by: F
                        ) -> tuple[I, I]:
    """Index pairs (i into a, j into b): a superset of the pairs with
    |ax_i - bx_j| <= half_x and |ay_i - by_j| <= half_y (one for all, or per point of a).
    The caller applies the exact test it needs.

    b is bucketed into strips of width `half_x` along x and sorted by (strip, y) as one
    float key, so that the points of one strip within a y interval are one run of the
    sorted keys: two `searchsorted` calls find, for every point of a, the runs in its
    own strip and the two beside it. Candidates cover 3 strips x 2 half_y around each
    point, not a whole 2 half_x wide band.
    """
    if len(ax) == 0 or len(bx) == 0:
        return _empty()
    width = half_x + _EPS        # a point exactly half_x away lands in a strip beside
    reach = float(np.max(half_y)) + _EPS
    ys = np.concatenate([ay, by])
    y0 = float(ys.min()) - reach
    # Keys of one strip span [0, span); every window stays inside its strip's span.
    span = float(ys.max()) + reach - y0 + 1.0
    keys = np.floor(bx / width) * span + (by - y0)
    order = np.argsort(keys)
    keys = keys[order]
    base = (np.floor(ax / width) + _STRIP_OFFSETS) * span + (ay - y0)    # (3, n)
    lo = np.searchsorted(keys, (base - (half_y + _EPS)).ravel(), "left")
    counts = np.searchsorted(keys, (base + (half_y + _EPS)).ravel(), "right") - lo
    total = int(counts.sum())
    if total == 0:
        return _empty()
    i, p = _expand(lo, counts, np.arange(3 * len(ax)) % len(ax), total)
    return i, order[p]
