"""From a ROI set and its labels to the evaluation, as plain data (JSON-ready dicts):
per verifier the ROC and AUC with a bootstrap interval, the confusion matrices at the
deployed threshold, at the verifier's own operating point and at the Youden-optimal
threshold, the threshold sweep over the verifier's own score range, the breakdown per
kind of negative and per stratum, warnings where a set is too small for its interval,
and ROI vs full-frame timing. tools/eval/tables.py renders it as Markdown, plots.py as
PNG.

Negatives are named for what stands there (`negative_category`): an empty scene (a
background ROI, a radar track on nothing), something flat on the road (a plate, a
manhole cover), something overhead (a sign), or a real structure (the lidar's and the
radar's returns on no labelled object: walls, poles, fences, trees, a guard rail; a
background ROI whose column holds lidar points standing at its range). A car
must not hit a real structure: keeping it out of the brake decision is the corridor's
job, not the camera's, so real structures are reported apart (the share the verifier
confirms) and never counted as false passes in the headline figures.
"""

import fnmatch
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aeb_radar_camera.tools.eval import metrics
from aeb_radar_camera.tools.eval.labels import AMBIGUOUS, NO, YES
from aeb_radar_camera.tools.eval.options import PAPER_SWEEP
from aeb_radar_camera.tools.eval.records import (
    KIND_BACKGROUND,
    KIND_BACKGROUND_STANDING,
    KIND_LIDAR,
    KIND_RADAR,
    KIND_TRACK,
    RoiRecord,
)
from aeb_radar_camera.tools.eval.scoring import PAPER_GATE

PAPER_TAU = 0.025
# Range bands of the strata: near (the paper's 8 m example), middle, far.
RANGE_BANDS = ((3.0, 8.0), (8.0, 15.0), (15.0, 25.0))
CLEAR_VIEW = ", clear view"
# Scores that are an edge density (the verifier's GateResult.score_name) and, for sets
# written before verifiers named their score, the verifiers that score one: the paper's
# thresholds are theirs.
DENSITY_SCORE = "edge_density"
DENSITY_VERIFIERS = frozenset({"edge_density", "adaptive_edge_density"})
# Other verifiers' sweep: their YES scores at these quantiles (score >= threshold keeps
# about 99 %, 95 %, ... 10 % of the obstacles), and their own tau.
SWEEP_QUANTILES = (0.01, 0.05, 0.10, 0.25, 0.50, 0.75, 0.90)
# Fewer YES or NO than this (or fewer resampled groups) and an interval means little.
MIN_FOR_INTERVAL = 10

# What stands at a negative ROI (negative_category).
EMPTY_SCENE = "empty scene"
FLAT = "flat"
OVERHEAD = "overhead"
REAL_STRUCTURE = "real structure"
LABELLED_NO = "labelled NO"
OTHER = "other"
# The simulator's false targets (tools/messages.py ObjectKind) by what they are.
CATEGORY_OF_CLASS = {"plate": FLAT, "sign": OVERHEAD, "guard_rail": REAL_STRUCTURE,
                     "ghost": EMPTY_SCENE}
CATEGORY_ORDER = (EMPTY_SCENE, FLAT, OVERHEAD, LABELLED_NO, OTHER, REAL_STRUCTURE)


@dataclass(frozen=True)
class ReportSettings:
    # The thresholds of Table IV for every verifier; None: each verifier's own range
    # (sweep_taus).
    taus: tuple[float, ...] | None = None
    # The deployed threshold of Table III; None: the verifier's own `tau` parameter.
    tau: float | None = None
    ci_group: str = "frame"            # frame | session | roi
    n_boot: int = 2000
    level: float = 0.95
    seed: int = 0
    # (name, glob on the session) pairs: the session groups of Table V.
    groups: tuple[tuple[str, str], ...] = ()
    # Count real structures as negatives (false passes) as figures before did.
    structures_as_negatives: bool = False


@dataclass
class Labelled:
    """The ROIs one verifier can be judged on: labelled YES/NO and applicable."""

    records: list[RoiRecord]
    scores: np.ndarray
    verdicts: np.ndarray
    truth: np.ndarray
    cannot_tell: np.ndarray      # the verifier said it could not tell (not verified)
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


def negative_category(r: RoiRecord) -> str:
    """What stands at a negative ROI: EMPTY_SCENE, FLAT, OVERHEAD, REAL_STRUCTURE,
    LABELLED_NO (a person said NO; what is there is not known) or OTHER."""
    if r.kind == KIND_BACKGROUND:
        return EMPTY_SCENE
    if r.kind in (KIND_LIDAR, KIND_RADAR, KIND_BACKGROUND_STANDING):
        return REAL_STRUCTURE
    if r.kind == KIND_TRACK:
        if r.obj_class in CATEGORY_OF_CLASS:
            return CATEGORY_OF_CLASS[r.obj_class]
        if r.truth == NO and not r.obj_class:
            return EMPTY_SCENE          # the simulator's truth: a track on no object
        return LABELLED_NO
    return OTHER


def negative_member(r: RoiRecord) -> str:
    """The ROI kind within its category (how the ROI was made)."""
    if r.kind == KIND_TRACK:
        return f"track on {r.obj_class or 'no object'}" if r.truth is not None else "track"
    return {KIND_LIDAR: "lidar structure", KIND_RADAR: "radar returns",
            KIND_BACKGROUND_STANDING: "background, lidar standing at its range"
            }.get(r.kind, r.kind)


def sweep_taus(verifier: str, scores: np.ndarray, truth: np.ndarray, tau: float | None,
               given: tuple[float, ...] | None, score_name: str = ""
               ) -> tuple[tuple[float, ...], str]:
    """(thresholds, what they are) of a verifier's Table IV: `given` for every verifier;
    else the paper's for an edge density (`score_name`, what the verifier says its score
    is; by the verifier's name where it said nothing); else its YES scores at SWEEP_QUANTILES (all
    its scores without a YES) and its own tau, so that every row means something on its
    own scale."""
    if given:
        return tuple(given), "given (--taus)"
    if score_name == DENSITY_SCORE or (not score_name and verifier.partition(":")[0]
                                       in DENSITY_VERIFIERS):
        return PAPER_SWEEP, "the paper's thresholds (edge density)"
    base = scores[truth] if truth.any() else scores
    if len(base) == 0:
        return (() if tau is None else (tau,)), "its own tau"
    values = {float(v) for v in np.quantile(base, SWEEP_QUANTILES, method="lower")}
    if tau is not None:
        values.add(float(tau))
    which = "YES" if truth.any() else "all"
    return (tuple(sorted(values)),
            f"its own score range: its {which} scores at quantiles "
            f"{', '.join(f'{q:g}' for q in SWEEP_QUANTILES)}"
            + (" and its tau" if tau is not None else ""))


def few_warning(n_yes: int, n_no: int, groups: int | None, what: str) -> str | None:
    """Why an interval on this set means little, or None."""
    parts = []
    if n_yes < MIN_FOR_INTERVAL:
        parts.append(f"{n_yes} YES")
    if n_no < MIN_FOR_INTERVAL:
        parts.append(f"{n_no} NO")
    if groups is not None and groups < MIN_FOR_INTERVAL:
        parts.append(f"{groups} resampled groups")
    if not parts:
        return None
    return (f"{what}: only {' and '.join(parts)} (fewer than {MIN_FOR_INTERVAL}): too few "
            "for its interval; a check, not a measurement")


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
    cannot = np.array([r.scores[verifier].cannot_tell for r in kept], dtype=bool)
    return Labelled(kept, scores, verdicts, truth, cannot, counts)


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
                "why": "needs YES and NO",
                "few": few_warning(n_yes, n_no, None, "AUC")}
    ci = metrics.bootstrap_auc(scores, truth, groups, s.n_boot, s.level, s.seed)
    return {"auc": metrics.auc(scores, truth), "ci": [ci.low, ci.high], "level": ci.level,
            "replicates": ci.replicates, "groups": ci.groups, "n_yes": n_yes, "n_no": n_no,
            "few": few_warning(n_yes, n_no, ci.groups if groups is not None else None,
                               "AUC")}


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


def _subset(sel: Labelled, keep: np.ndarray) -> Labelled:
    return Labelled([r for r, k in zip(sel.records, keep, strict=True) if k],
                    sel.scores[keep], sel.verdicts[keep], sel.truth[keep],
                    sel.cannot_tell[keep], dict(sel.counts))


def _structures(sel: Labelled, mask: np.ndarray, tau: float | None) -> dict[str, Any]:
    """The real structures among the negatives: how many, of what kind, and the share
    the verifier confirms (passes), which is what it should do with them."""
    members: dict[str, int] = {}
    for r, m in zip(sel.records, mask, strict=True):
        if m:
            members[negative_member(r)] = members.get(negative_member(r), 0) + 1
    n = int(mask.sum())
    out: dict[str, Any] = {"n": n, "members": members,
                           "confirmed_operating": float(sel.verdicts[mask].mean()) if n
                           else None,
                           "median_score": float(np.median(sel.scores[mask])) if n else None}
    if tau is not None:
        out["confirmed_tau"] = float((sel.scores[mask] >= tau).mean()) if n else None
    return out


def evaluate(records: Sequence[RoiRecord], labels: dict[str, str], verifier: str,
             params: dict[str, Any], settings: ReportSettings) -> dict[str, Any]:
    """Everything about one verifier on the labelled ROIs: obstacles (YES) against the
    negatives a camera may reject; real structures apart (see the module's doc). Raises
    ValueError when there is nothing labelled to judge."""
    every = select(records, labels, verifier)
    if every.counts["labelled"] == 0:
        raise ValueError(f"{verifier}: no labelled ROI it applies to ({every.counts})")
    s = settings
    tau = s.tau if s.tau is not None else _tau_of(params)
    structure = np.array([not y and negative_category(r) == REAL_STRUCTURE
                          for r, y in zip(every.records, every.truth, strict=True)],
                         dtype=bool)
    sel = every if s.structures_as_negatives else _subset(every, ~structure)
    out: dict[str, Any] = {"verifier": verifier, "params": params, "counts": every.counts,
                           "n": len(sel.records), "n_yes": int(sel.truth.sum()),
                           "n_no": int((~sel.truth).sum()), "tau": tau,
                           "structures_as_negatives": s.structures_as_negatives}
    out["real_structure"] = _structures(every, structure, tau)
    groups = _group_keys(sel.records, s.ci_group)
    out["ci_group"] = s.ci_group
    out.update(auc_block(sel.scores, sel.truth, groups, s))
    out["operating"] = metrics.confusion(sel.verdicts, sel.truth).as_dict()
    out["cannot_tell"] = {"yes": int((sel.cannot_tell & sel.truth).sum()),
                          "no": int((sel.cannot_tell & ~sel.truth).sum()),
                          "real_structure": int((every.cannot_tell & structure).sum())}
    if tau is not None:
        out["at_tau"] = metrics.at_threshold(sel.scores, sel.truth, tau).as_dict()
    if out["auc"] is not None:
        r = metrics.roc(sel.scores, sel.truth)
        out["roc"] = {"fpr": r.fpr.tolist(), "tpr": r.tpr.tolist(),
                      "thresholds": [None if math.isinf(t) else t for t in r.thresholds]}
        y_tau, j = metrics.youden(sel.scores, sel.truth)
        out["youden"] = {"tau": y_tau, "j": j,
                         **metrics.at_threshold(sel.scores, sel.truth, y_tau).as_dict()}
    names = {r.scores[verifier].score_name for r in every.records}
    out["score_name"] = names.pop() if len(names) == 1 else ""
    taus, basis = sweep_taus(verifier, sel.scores, sel.truth, tau, s.taus, out["score_name"])
    out["sweep_basis"] = basis
    out["sweep"] = [{"tau": t, **c.as_dict()}
                    for t, c in metrics.sweep(sel.scores, sel.truth, taus)]
    out["negative_kinds"] = _negative_kinds(every, _group_keys(every.records, s.ci_group),
                                            tau, taus, s)
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
    out["score_by_class"] = _score_summary(every)
    out["timing_us"] = _timing(every.records, verifier)
    out["warnings"] = _warnings(out)
    return out


def _warnings(ev: dict[str, Any]) -> list[str]:
    """Every figure of `ev` whose set is too small for its interval, named."""
    out = []
    if ev.get("few"):
        out.append(f"{ev['verifier']}: {ev['few']}")
    for k in ev["negative_kinds"]:
        if k.get("few"):
            out.append(f"{ev['verifier']} vs {k['kind']}: {k['few']}")
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
                               "cannot_tell": int(sel.cannot_tell[idx].sum()),
                               "median_score": float(np.median(sel.scores[idx]))}
        if tau is not None:
            row["recall_tau"] = float((sel.scores[idx] >= tau).mean())
        out.append(row)
    return out


def _negative_kinds(sel: Labelled, groups: list[str] | None, tau: float | None,
                    taus: Sequence[float], s: ReportSettings) -> list[dict[str, Any]]:
    """Every YES against the NOs of one category (negative_category): how well the
    verifier tells obstacles from that kind of negative, and how many of them pass (for
    real structures: how many it confirms, as it should)."""
    cats = [negative_category(r) for r in sel.records]
    present = {c for c, y in zip(cats, sel.truth, strict=True) if not y}
    kinds = [c for c in CATEGORY_ORDER if c in present]
    # A kind whose negatives sometimes have an object in view is also judged on the others.
    clear = [f"{k}{CLEAR_VIEW}" for k in kinds
             if any(r.object_in_view for r, c, y in zip(sel.records, cats, sel.truth,
                                                       strict=True) if c == k and not y)]
    out = []
    for kind in kinds + clear:
        base = kind.removesuffix(CLEAR_VIEW)
        only_clear = kind != base
        idx = np.array([bool(y) or (c == base and not (only_clear and r.object_in_view))
                        for r, c, y in zip(sel.records, cats, sel.truth, strict=True)])
        neg = idx & ~sel.truth
        g = None if groups is None else [k for k, keep in zip(groups, idx, strict=True)
                                         if keep]
        members: dict[str, int] = {}
        for r, m in zip(sel.records, neg, strict=True):
            if m:
                members[negative_member(r)] = members.get(negative_member(r), 0) + 1
        row: dict[str, Any] = {"kind": kind, "n_no": int(neg.sum()), "members": members,
                               "real_structure": base == REAL_STRUCTURE}
        row.update(auc_block(sel.scores[idx], sel.truth[idx], g, s))
        if row["auc"] is not None:
            curve = metrics.roc(sel.scores[idx], sel.truth[idx])
            row["roc"] = {"fpr": curve.fpr.tolist(), "tpr": curve.tpr.tolist()}
        row["pass_rate_operating"] = float(sel.verdicts[neg].mean())
        row["cannot_tell_rate"] = float(sel.cannot_tell[neg].mean())
        row["operating"] = metrics.confusion(sel.verdicts[idx], sel.truth[idx]).as_dict()
        if tau is not None:
            row["pass_rate_tau"] = float((sel.scores[neg] >= tau).mean())
        row["pass_rate_sweep"] = {f"{t:g}": float((sel.scores[neg] >= t).mean())
                                  for t in taus}
        row["median_score"] = float(np.median(sel.scores[neg]))
        out.append(row)
    return out


def _score_summary(sel: Labelled) -> dict[str, dict[str, float]]:
    """Median and quartiles of the score for YES and for each kind of NO."""
    out = {}
    buckets: dict[str, list[float]] = {}
    for r, y, v in zip(sel.records, sel.truth, sel.scores, strict=True):
        buckets.setdefault("YES" if y else f"NO {negative_category(r)}", []).append(float(v))
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
