"""Near pairs between two point sets, without a dense n x m matrix."""

import numpy as np
import numpy.typing as npt

F = npt.NDArray[np.float64]
I = npt.NDArray[np.int64]  # noqa: E741

# Up to this many candidate pairs a dense matrix is cheaper: fewer numpy calls, and a
# call costs more than a few thousand elements.
_DENSE_MAX = 4096


def pairs_within(ax: F, ay: F, bx: F, by: F, radius: float) -> tuple[I, I]:
    """Index pairs (i into a, j into b) whose Euclidean distance is at most `radius`.

    Candidates come from a window on b sorted by x, so the cost grows with the number
    of near pairs, not with n * m (a dense 250 x 250 distance matrix costs milliseconds
    on a small CPU; this costs tens of microseconds).
    """
    if len(ax) == 0 or len(bx) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    if len(ax) * len(bx) <= _DENSE_MAX:
        dx = ax[:, None] - bx[None, :]
        dy = ay[:, None] - by[None, :]
        i, j = np.nonzero(dx * dx + dy * dy <= radius * radius)
        return i, j
    order = np.argsort(bx, kind="stable")
    xs = bx[order]
    lo = np.searchsorted(xs, ax - radius, "left")
    counts = np.searchsorted(xs, ax + radius, "right") - lo
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    i = np.repeat(np.arange(len(ax)), counts)
    first = np.repeat(lo - (np.cumsum(counts) - counts), counts)
    j = order[first + np.arange(total)]
    dx = ax[i] - bx[j]
    dy = ay[i] - by[j]
    keep = dx * dx + dy * dy <= radius * radius
    return i[keep], j[keep]


def pairs_within_self(x: F, y: F, radius: float) -> tuple[I, I]:
    """Index pairs (i, j) of one point set, each unordered pair once, whose distance is
    at most `radius` (half the candidates of `pairs_within(x, y, x, y, r)`)."""
    n = len(x)
    if n < 2:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    if n * n <= _DENSE_MAX:
        i, j = pairs_within(x, y, x, y, radius)
        upper = i < j
        return i[upper], j[upper]
    order = np.argsort(x, kind="stable")
    xs, ys = x[order], y[order]
    counts = np.searchsorted(xs, xs + radius, "right") - np.arange(1, n + 1)
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    p = np.repeat(np.arange(n), counts)
    q = p + 1 + np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
    dx = xs[q] - xs[p]
    dy = ys[q] - ys[p]
    keep = dx * dx + dy * dy <= radius * radius
    return order[p[keep]], order[q[keep]]
