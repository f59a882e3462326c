"""From a ROI set and its labels to the evaluation, as plain data (JSON-ready dicts):
per verifier the ROC and AUC with a bootstrap interval, the confusion matrices at the
deployed threshold, at the verifier's own operating point and at the Youden-optimal
threshold, the threshold sweep, the breakdown per negative kind and per stratum, and
ROI vs full-frame timing. tools/eval/tables.py renders it as Markdown, plots.py as PNG.
"""

import fnmatch
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tools.eval import metrics
from tools.eval.labels import AMBIGUOUS, NO, YES
from tools.eval.records import RoiRecord
from tools.eval.scoring import PAPER_GATE

PAPER_SWEEP = (0.010, 0.025, 0.050, 0.080, 0.100, 0.150)
PAPER_TAU = 0.025
# Range bands of the strata: near (the paper's 8 m example), middle, far.
RANGE_BANDS = ((3.0, 8.0), (8.0, 15.0), (15.0, 25.0))
CLEAR_VIEW = ", clear view"


@dataclass(frozen=True)
class ReportSettings:
    taus: tuple[float, ...] = PAPER_SWEEP
    # The deployed threshold of Table III; None: the verifier's own `tau` parameter.
    tau: float | None = None
    ci_group: str = "frame"            # frame | session | roi
    n_boot: int = 2000
    level: float = 0.95
    seed: int = 0
    # (name, glob on the session) pairs: the session groups of Table V.
    groups: tuple[tuple[str, str], ...] = ()


@dataclass
class Labelled:
    """The ROIs one verifier can be judged on: labelled YES/NO and applicable."""

    records: list[RoiRecord]
    scores: np.ndarray
    verdicts: np.ndarray
    truth: np.ndarray
    counts: dict[str, int] = field(default_factory=dict)


def session_group(session: str, groups: Sequence[tuple[str, str]]) -> str:
    for name, pattern in groups:
        if fnmatch.fnmatchcase(session, pattern):
            return name
    return "other" if groups else ""


def range_band(r: float) -> str:
    for lo, hi in RANGE_BANDS:
        if lo <= r < hi or (hi == RANGE_BANDS[-1][1] and r == hi):
            return f"{lo:g}-{hi:g} m"
    return "out of 3-25 m"


def select(records: Sequence[RoiRecord], labels: dict[str, str], verifier: str) -> Labelled:
    """The labelled, applicable ROIs of `verifier`, and how many were left out why."""
    kept: list[RoiRecord] = []
    counts = {"labelled": 0, "ambiguous": 0, "unlabelled": 0, "not_applicable": 0,
              "not_scored": 0}
    for r in records:
        value = labels.get(r.id)
        if value is None:
            counts["unlabelled"] += 1
            continue
        if value == AMBIGUOUS:
            counts["ambiguous"] += 1
            continue
        sc = r.scores.get(verifier)
        if sc is None:
            counts["not_scored"] += 1
            continue
        if sc.score is None:
            counts["not_applicable"] += 1
            continue
        counts["labelled"] += 1
        kept.append(r)
    scores = np.array([r.scores[verifier].score for r in kept], dtype=np.float64)
    verdicts = np.array([bool(r.scores[verifier].verified) for r in kept], dtype=bool)
    truth = np.array([labels[r.id] == YES for r in kept], dtype=bool)
    return Labelled(kept, scores, verdicts, truth, counts)


def _group_keys(records: Sequence[RoiRecord], how: str) -> list[str] | None:
    if how == "roi":
        return None
    if how == "session":
        return [f"{r.source}/{r.session}" for r in records]
    if how == "frame":
        return [f"{r.source}/{r.session}/{r.frame}" for r in records]
    raise ValueError(f"ci group {how!r}: expected frame, session or roi")


def auc_block(scores: np.ndarray, truth: np.ndarray, groups: list[str] | None,
              s: ReportSettings) -> dict[str, Any]:
    """AUC and its interval, or the reason there is none."""
    n_yes, n_no = int(truth.sum()), int((~truth).sum())
    if n_yes == 0 or n_no == 0:
        return {"auc": None, "ci": None, "n_yes": n_yes, "n_no": n_no,
                "why": "needs YES and NO"}
    ci = metrics.bootstrap_auc(scores, truth, groups, s.n_boot, s.level, s.seed)
    return {"auc": metrics.auc(scores, truth), "ci": [ci.low, ci.high], "level": ci.level,
            "replicates": ci.replicates, "groups": ci.groups, "n_yes": n_yes, "n_no": n_no}


def _tau_of(params: dict[str, Any]) -> float | None:
    tau = params.get("tau")
    return float(tau) if isinstance(tau, int | float) and not isinstance(tau, bool) else None


def _strata(sel: Labelled, key: Callable[[RoiRecord], str], tau: float | None,
            order: Sequence[str] = ()) -> list[dict[str, Any]]:
    """Per value of `key` (those in `order` first, in that order, then the others
    sorted): n, confusion at the operating point (and at tau), AUC."""
    present = {key(r) for r in sel.records}
    names = [n for n in order if n in present] + sorted(present - set(order))
    out = []
    for name in names:
        idx = np.array([key(r) == name for r in sel.records], dtype=bool)
        y, sc = sel.truth[idx], sel.scores[idx]
        row: dict[str, Any] = {"name": name, "n": int(idx.sum()), "n_yes": int(y.sum()),
                               "n_no": int((~y).sum()),
                               "operating": metrics.confusion(sel.verdicts[idx], y).as_dict()}
        if tau is not None:
            row["at_tau"] = metrics.confusion(sc >= tau, y).as_dict()
        row["auc"] = metrics.auc(sc, y) if 0 < y.sum() < len(y) else None
        out.append(row)
    return out


def evaluate(records: Sequence[RoiRecord], labels: dict[str, str], verifier: str,
             params: dict[str, Any], settings: ReportSettings) -> dict[str, Any]:
    """Everything about one verifier on the labelled ROIs. Raises ValueError when there
    is nothing labelled to judge."""
    sel = select(records, labels, verifier)
    if sel.counts["labelled"] == 0:
        raise ValueError(f"{verifier}: no labelled ROI it applies to ({sel.counts})")
    s = settings
    tau = s.tau if s.tau is not None else _tau_of(params)
    out: dict[str, Any] = {"verifier": verifier, "params": params, "counts": sel.counts,
                           "n": len(sel.records), "n_yes": int(sel.truth.sum()),
                           "n_no": int((~sel.truth).sum()), "tau": tau}
    groups = _group_keys(sel.records, s.ci_group)
    out["ci_group"] = s.ci_group
    out.update(auc_block(sel.scores, sel.truth, groups, s))
    out["operating"] = metrics.confusion(sel.verdicts, sel.truth).as_dict()
    if tau is not None:
        out["at_tau"] = metrics.at_threshold(sel.scores, sel.truth, tau).as_dict()
    if out["auc"] is not None:
        r = metrics.roc(sel.scores, sel.truth)
        out["roc"] = {"fpr": r.fpr.tolist(), "tpr": r.tpr.tolist(),
                      "thresholds": [None if math.isinf(t) else t for t in r.thresholds]}
        y_tau, j = metrics.youden(sel.scores, sel.truth)
        out["youden"] = {"tau": y_tau, "j": j,
                         **metrics.at_threshold(sel.scores, sel.truth, y_tau).as_dict()}
    out["sweep"] = [{"tau": t, **c.as_dict()}
                    for t, c in metrics.sweep(sel.scores, sel.truth, s.taus)]
    out["negative_kinds"] = _negative_kinds(sel, groups, tau, s)
    out["strata"] = {
        "lighting": _strata(sel, lambda r: r.lighting or "unknown", tau),
        "range": _strata(sel, lambda r: range_band(r.range_m), tau,
                         [f"{lo:g}-{hi:g} m" for lo, hi in RANGE_BANDS]),
        "kind": _strata(sel, lambda r: r.kind, tau),
        "camera": _strata(sel, lambda r: r.camera, tau),
    }
    out["recall_by_class"] = _recall_by_class(sel, tau)
    if s.groups:
        out["strata"]["group"] = _strata(sel, lambda r: session_group(r.session, s.groups),
                                         tau, [name for name, _ in s.groups])
    out["score_by_class"] = _score_summary(sel)
    out["timing_us"] = _timing(sel.records, verifier)
    return out


def _recall_by_class(sel: Labelled, tau: float | None) -> list[dict[str, Any]]:
    """Per object class of the YES ROIs: how many pass."""
    by: dict[str, list[int]] = {}
    for i, (r, y) in enumerate(zip(sel.records, sel.truth, strict=True)):
        if y:
            by.setdefault(r.obj_class or "unknown", []).append(i)
    out = []
    for name, idx in sorted(by.items()):
        row: dict[str, Any] = {"class": name, "n": len(idx),
                               "recall_operating": float(sel.verdicts[idx].mean()),
                               "median_score": float(np.median(sel.scores[idx]))}
        if tau is not None:
            row["recall_tau"] = float((sel.scores[idx] >= tau).mean())
        out.append(row)
    return out


def _negative_kinds(sel: Labelled, groups: list[str] | None, tau: float | None,
                    s: ReportSettings) -> list[dict[str, Any]]:
    """Every YES against the NOs of one kind: how well the verifier tells obstacles from
    that kind of negative, and how many of them pass."""
    kinds = sorted({r.kind for r, y in zip(sel.records, sel.truth, strict=True) if not y})
    # A kind whose negatives sometimes have an object in view is also judged on the others.
    clear = [f"{k}{CLEAR_VIEW}" for k in kinds
             if any(r.object_in_view for r in sel.records if r.kind == k)]
    out = []
    for kind in kinds + clear:
        base = kind.removesuffix(CLEAR_VIEW)
        only_clear = kind != base
        idx = np.array([bool(y) or (r.kind == base and not (only_clear and r.object_in_view))
                        for r, y in zip(sel.records, sel.truth, strict=True)])
        neg = idx & ~sel.truth
        g = None if groups is None else [k for k, keep in zip(groups, idx, strict=True)
                                         if keep]
        row: dict[str, Any] = {"kind": kind, "n_no": int(neg.sum())}
        row.update(auc_block(sel.scores[idx], sel.truth[idx], g, s))
        if row["auc"] is not None:
            r = metrics.roc(sel.scores[idx], sel.truth[idx])
            row["roc"] = {"fpr": r.fpr.tolist(), "tpr": r.tpr.tolist()}
        row["pass_rate_operating"] = float(sel.verdicts[neg].mean())
        row["operating"] = metrics.confusion(sel.verdicts[idx], sel.truth[idx]).as_dict()
        if tau is not None:
            row["pass_rate_tau"] = float((sel.scores[neg] >= tau).mean())
        row["pass_rate_sweep"] = {f"{t:g}": float((sel.scores[neg] >= t).mean())
                                  for t in s.taus}
        row["median_score"] = float(np.median(sel.scores[neg]))
        out.append(row)
    return out


def _score_summary(sel: Labelled) -> dict[str, dict[str, float]]:
    """Median and quartiles of the score for YES and for each kind of NO."""
    out = {}
    buckets: dict[str, list[float]] = {}
    for r, y, v in zip(sel.records, sel.truth, sel.scores, strict=True):
        buckets.setdefault("YES" if y else f"NO {r.kind}", []).append(float(v))
    for name, vals in sorted(buckets.items()):
        a = np.array(vals)
        out[name] = {"n": len(a), "median": float(np.median(a)),
                     "q25": float(np.quantile(a, 0.25)), "q75": float(np.quantile(a, 0.75))}
    return out


def _stats(values: Sequence[float]) -> dict[str, float] | None:
    if not values:
        return None
    a = np.asarray(values, dtype=np.float64)
    return {"n": len(a), "mean": float(a.mean()), "std": float(a.std(ddof=1)) if len(a) > 1
            else 0.0, "p50": float(np.percentile(a, 50)), "p95": float(np.percentile(a, 95))}


def _timing(records: Sequence[RoiRecord], verifier: str) -> dict[str, Any]:
    roi = [r.scores[verifier].us for r in records if verifier in r.scores]
    return {"roi": _stats(roi)}


def timing_table(records: Sequence[RoiRecord], verifier: str = "edge_density"
                 ) -> dict[str, Any]:
    """Table II: time per ROI against full-frame Canny, over every ROI (labelled or not),
    and the ROI's share of the frame near 8 m and near 25 m."""
    roi = [r.scores[verifier].us for r in records
           if verifier in r.scores and r.scores[verifier].score is not None]
    full = [r.frame_canny_us for r in records if r.frame_canny_us is not None]
    rs, fs = _stats(roi), _stats(full)
    out: dict[str, Any] = {"verifier": verifier, "roi_us": rs, "frame_us": fs,
                           "frames": len({(r.source, r.session, r.frame) for r in records}),
                           "sessions": len({(r.source, r.session) for r in records})}
    if rs and fs:
        out["mean_ratio"] = fs["mean"] / rs["mean"] if rs["mean"] > 0 else None
        out["p95_ratio"] = fs["p95"] / rs["p95"] if rs["p95"] > 0 else None
    for at, (lo, hi) in (("8m", (7.5, 8.5)), ("25m", (24.0, 25.0))):
        share = [r.roi_area_pct for r in records if lo <= r.range_m <= hi]
        out[f"area_pct_{at}"] = float(np.median(share)) if share else None
    return out


def evaluate_all(records: Sequence[RoiRecord], labels: dict[str, str],
                 verifiers: dict[str, dict[str, Any]], settings: ReportSettings
                 ) -> dict[str, Any]:
    """Every verifier that has labelled, applicable ROIs; the others with the reason."""
    out: dict[str, Any] = {"verifiers": {}, "skipped": {},
                           "labels": {v: sum(1 for x in labels.values() if x == v)
                                      for v in (YES, NO, AMBIGUOUS)},
                           "rois": len(records)}
    # The paper's gate first: the reference every other verifier is compared with.
    for name in sorted(verifiers, key=lambda n: (n != PAPER_GATE, n)):
        params = verifiers[name]
        try:
            out["verifiers"][name] = evaluate(records, labels, name, params, settings)
        except ValueError as exc:
            out["skipped"][name] = str(exc)
    out["timing"] = timing_table(records)
    return out
