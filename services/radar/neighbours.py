"""Near pairs between point sets, without a dense n x m matrix.

numpy calls cost microseconds each on a small CPU whatever their size, so at the sizes of
a radar cycle (tens to hundreds of points) the number of calls decides, not the number
of candidate pairs: a sort on x and a window per point (`pairs_within`,
`pairs_within_self`) beats finer structures up to a few hundred points. The tracker's
gate, with hundreds of tracks and detections in one window, uses a strip grid
(`candidates_in_boxes`): it yields about a quarter of the window's candidates.
"""

import numpy as np
import numpy.typing as npt

F = npt.NDArray[np.float64]
I = npt.NDArray[np.int64]  # noqa: E741

# Up to this many candidate pairs a dense matrix is cheaper: fewer numpy calls, and a
# call costs more than a few thousand elements.
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


def pairs_within(ax: F, ay: F, bx: F, by: F, radius: float) -> tuple[I, I]:
    """Index pairs (i into a, j into b) whose Euclidean distance is at most `radius`.

    Candidates come from a window on b sorted by x, so the cost grows with the number
    of near pairs, not with n * m (a dense 250 x 250 distance matrix costs milliseconds
    on a small CPU; this costs tens of microseconds).
    """
    if len(ax) == 0 or len(bx) == 0:
        return _empty()
    if len(ax) * len(bx) <= _DENSE_MAX:
        dx = ax[:, None] - bx[None, :]
        dy = ay[:, None] - by[None, :]
        i, j = np.nonzero(dx * dx + dy * dy <= radius * radius)
        return i, j
    order = np.argsort(bx, kind="stable")
    xs = bx[order]
    lo = np.searchsorted(xs, ax - (radius + _EPS), "left")
    counts = np.searchsorted(xs, ax + (radius + _EPS), "right") - lo
    total = int(counts.sum())
    if total == 0:
        return _empty()
    i, p = _expand(lo, counts, np.arange(len(ax)), total)
    j = order[p]
    dx = ax[i] - bx[j]
    dy = ay[i] - by[j]
    keep = dx * dx + dy * dy <= radius * radius
    return i[keep], j[keep]


def pairs_within_self(x: F, y: F, radius: float) -> tuple[I, I]:
    """Index pairs (i, j) of one point set, each unordered pair once, whose distance is
    at most `radius` (half the candidates of `pairs_within(x, y, x, y, r)`)."""
    n = len(x)
    if n < 2:
        return _empty()
    if n * n <= _DENSE_MAX:
        i, j = pairs_within(x, y, x, y, radius)
        upper = i < j
        return i[upper], j[upper]
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
