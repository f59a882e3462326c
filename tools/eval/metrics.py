"""Verification metrics from scores and YES/NO labels, numpy only (pure).

A verifier passes an ROI when `score >= tau` (the paper's rule, d(P) >= tau). The ROC
is computed at every distinct score; AUC is the Mann-Whitney statistic (ties count one
half), which equals the trapezoidal area under that ROC. Confidence intervals come from
a cluster bootstrap: whole groups (frames or sessions) are resampled with replacement,
because ROIs of one frame or drive are not independent.
"""

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Counts:
    """A confusion matrix; the ratios are NaN where their denominator is zero."""

    tp: int
    fp: int
    tn: int
    fn: int

    @property
    def n(self) -> int:
        return self.tp + self.fp + self.tn + self.fn

    @property
    def precision(self) -> float:
        return _ratio(self.tp, self.tp + self.fp)

    @property
    def recall(self) -> float:
        return _ratio(self.tp, self.tp + self.fn)

    @property
    def fpr(self) -> float:
        """Share of negatives that pass (false targets the gate lets through)."""
        return _ratio(self.fp, self.fp + self.tn)

    @property
    def f1(self) -> float:
        return _ratio(2 * self.tp, 2 * self.tp + self.fp + self.fn)

    @property
    def accuracy(self) -> float:
        return _ratio(self.tp + self.tn, self.n)

    def as_dict(self) -> dict[str, float | int | None]:
        return {"tp": self.tp, "fp": self.fp, "tn": self.tn, "fn": self.fn,
                "precision": _finite(self.precision), "recall": _finite(self.recall),
                "f1": _finite(self.f1), "accuracy": _finite(self.accuracy),
                "fpr": _finite(self.fpr)}


def _ratio(a: int, b: int) -> float:
    return a / b if b else math.nan


def _finite(x: float) -> float | None:
    return None if math.isnan(x) else x


def _arrays(scores: Sequence[float] | np.ndarray, labels: Sequence[bool] | np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    s = np.asarray(scores, dtype=np.float64).ravel()
    y = np.asarray(labels, dtype=bool).ravel()
    if s.shape != y.shape:
        raise ValueError(f"{len(s)} scores but {len(y)} labels")
    if not np.all(np.isfinite(s)):
        raise ValueError("scores must be finite numbers")
    return s, y


def confusion(passed: Sequence[bool] | np.ndarray, labels: Sequence[bool] | np.ndarray
              ) -> Counts:
    """Counts of verdicts (True: the verifier passed the ROI) against labels (True: YES)."""
    p = np.asarray(passed, dtype=bool).ravel()
    y = np.asarray(labels, dtype=bool).ravel()
    if p.shape != y.shape:
        raise ValueError(f"{len(p)} verdicts but {len(y)} labels")
    return Counts(int(np.sum(p & y)), int(np.sum(p & ~y)), int(np.sum(~p & ~y)),
                  int(np.sum(~p & y)))


def at_threshold(scores: Sequence[float] | np.ndarray, labels: Sequence[bool] | np.ndarray,
                 tau: float) -> Counts:
    """The confusion matrix of the rule score >= tau."""
    s, y = _arrays(scores, labels)
    return confusion(s >= tau, y)


@dataclass(frozen=True)
class Roc:
    """ROC points at every distinct score, from the strictest (nothing passes, threshold
    +inf) to the most permissive (everything passes, the lowest score)."""

    thresholds: np.ndarray
    tpr: np.ndarray
    fpr: np.ndarray
    auc: float


def roc(scores: Sequence[float] | np.ndarray, labels: Sequence[bool] | np.ndarray) -> Roc:
    """Raises ValueError without at least one YES and one NO."""
    s, y = _arrays(scores, labels)
    n_pos, n_neg = int(y.sum()), int((~y).sum())
    if n_pos == 0 or n_neg == 0:
        raise ValueError(f"an ROC needs both classes (YES {n_pos}, NO {n_neg})")
    order = np.argsort(-s, kind="mergesort")
    s_sorted, y_sorted = s[order], y[order]
    # The last index of each run of equal scores: the point where that score passes.
    last = np.r_[np.flatnonzero(np.diff(s_sorted) != 0), len(s_sorted) - 1]
    tp = np.cumsum(y_sorted)[last]
    fp = np.cumsum(~y_sorted)[last]
    tpr = np.r_[0.0, tp / n_pos]
    fpr = np.r_[0.0, fp / n_neg]
    return Roc(np.r_[np.inf, s_sorted[last]], tpr, fpr, auc(s, y))


def auc(scores: Sequence[float] | np.ndarray, labels: Sequence[bool] | np.ndarray) -> float:
    """P(score of a YES > score of a NO) + P(equal) / 2. Raises ValueError without both
    classes."""
    s, y = _arrays(scores, labels)
    value = _weighted_auc(s, y, np.ones((1, len(s))))[0]
    if math.isnan(value):
        raise ValueError("AUC needs at least one YES and one NO")
    return float(value)


def _weighted_auc(s: np.ndarray, y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """AUC under each row of sample weights `w` (R, N) at once: one sort for all rows.

    Per distinct score v: every YES at v beats the NO weight below v and ties with the NO
    weight at v. NaN for a row without YES or NO weight.
    """
    uniq, inverse = np.unique(s, return_inverse=True)
    k = len(uniq)
    rows = w.shape[0]
    pos = np.zeros((rows, k))
    neg = np.zeros((rows, k))
    np.add.at(pos.T, inverse[y], w[:, y].T)
    np.add.at(neg.T, inverse[~y], w[:, ~y].T)
    neg_below = np.cumsum(neg, axis=1) - neg
    wins = np.sum(pos * (neg_below + 0.5 * neg), axis=1)
    total = pos.sum(axis=1) * neg.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, wins / np.where(total > 0, total, 1.0), np.nan)


@dataclass(frozen=True)
class Interval:
    low: float
    high: float
    level: float
    replicates: int       # bootstrap samples that had both classes
    groups: int


def bootstrap_auc(scores: Sequence[float] | np.ndarray, labels: Sequence[bool] | np.ndarray,
                  groups: Sequence[str] | np.ndarray | None = None, n_boot: int = 2000,
                  level: float = 0.95, seed: int = 0) -> Interval:
    """Percentile interval of the AUC, resampling whole groups (None: each ROI its own
    group). Raises ValueError without both classes."""
    s, y = _arrays(scores, labels)
    auc(s, y)                                   # raises without both classes
    g = np.arange(len(s)) if groups is None else np.unique(np.asarray(groups),
                                                           return_inverse=True)[1]
    n_groups = int(g.max()) + 1
    rng = np.random.default_rng(seed)
    values: list[np.ndarray] = []
    block = max(1, min(n_boot, 2_000_000 // max(len(s), 1)))
    for start in range(0, n_boot, block):
        rows = min(block, n_boot - start)
        picks = rng.integers(0, n_groups, size=(rows, n_groups))
        per_group = np.zeros((rows, n_groups))
        np.add.at(per_group, (np.repeat(np.arange(rows), n_groups), picks.ravel()), 1.0)
        values.append(_weighted_auc(s, y, per_group[:, g]))
    all_values = np.concatenate(values)
    ok = all_values[~np.isnan(all_values)]
    alpha = (1.0 - level) / 2.0
    lo, hi = (np.quantile(ok, [alpha, 1.0 - alpha]) if len(ok) else (math.nan, math.nan))
    return Interval(float(lo), float(hi), level, len(ok), n_groups)


def youden(scores: Sequence[float] | np.ndarray, labels: Sequence[bool] | np.ndarray
           ) -> tuple[float, float]:
    """(threshold, J) maximising J = TPR - FPR over the distinct scores; of equal J the
    lowest threshold (the higher recall). Raises ValueError without both classes."""
    r = roc(scores, labels)
    j = r.tpr - r.fpr
    best = np.flatnonzero(j == j.max())[-1]
    return float(r.thresholds[best]), float(j[best])


def sweep(scores: Sequence[float] | np.ndarray, labels: Sequence[bool] | np.ndarray,
          taus: Sequence[float]) -> list[tuple[float, Counts]]:
    s, y = _arrays(scores, labels)
    return [(float(t), confusion(s >= t, y)) for t in taus]
