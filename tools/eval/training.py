"""The training behind `aeb train-verifier` (tools/eval/train_verifier.py): which labelled
ROIs it may train on (folds of frames by content, simulator seeds of the `train` split,
never the demo's scenarios), the HOG descriptors cut by the verifier's own code, an
L2-regularised logistic regression fitted by Newton's method, the threshold chosen by
cross-validation inside the training frames, and the record of what it was trained on.
"""

import hashlib
import re
import sys
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from aeb_radar_camera.services.fusion.roi import Roi
from aeb_radar_camera.services.fusion.verifiers import Observation
from aeb_radar_camera.services.fusion.verifiers.appearance import (
    HogLinearModel,
    hog_linear_features,
)
from aeb_radar_camera.tools.eval import labels as labelfile
from aeb_radar_camera.tools.eval.frames import FrameLoadError, load_gray, record_digest
from aeb_radar_camera.tools.eval.records import FrameRef, RoiRecord, read_records

# A generated case's scenario name ends in its seed (tools/sim/families.py: Case.name).
CASE_SEED = re.compile(r"_s(\d+)$")
TRAIN_SPLIT = "train"


class TrainingError(ValueError):
    """Training data that cannot train a classifier; the message says why."""


@dataclass(frozen=True)
class TrainOptions:
    rois: str
    labels: str | None = None
    folds: int = 1
    fold: int = 0
    seeds: str = ""                 # a tools.sim.families seed spec, "" for no filter
    recall: float = 0.99
    cv_folds: int = 4
    l2: float = 300.0
    window: tuple[int, int] = (32, 64)
    context: float = 1.25


def fold_of(digest: str, folds: int) -> int:
    """The fold of a frame by its content digest (frames.frame_digest): the same picture
    gets the same fold under any path or name, on every machine. SHA-256, not CRC-32:
    a CRC is linear, so the folds of "cv:" + key and of key would be tied (with two
    folds, exactly opposite) and the cross-validation inside a fold would have none."""
    return int.from_bytes(hashlib.sha256(digest.encode()).digest()[:8], "little") % folds


def case_seed(scenario: str) -> int | None:
    """The seed of a generated case's scenario name, None for any other scenario."""
    m = CASE_SEED.search(scenario)
    return int(m.group(1)) if m else None


def training_seeds(spec: str) -> list[int]:
    """The seeds of `spec` (tools.sim.families.seeds_of), all of the `train` split.
    Raises TrainingError for a bad spec or a seed outside `train`."""
    from aeb_radar_camera.tools.sim.families import SPLITS, describe_splits, seeds_of, split_of

    try:
        seeds = seeds_of(spec)
        outside = sorted({s for s in seeds if split_of(s) != TRAIN_SPLIT})
    except ValueError as exc:
        raise TrainingError(f"--seeds {spec!r}: {exc}") from exc
    if not seeds:
        raise TrainingError(f"--seeds {spec!r}: no seed")
    if outside:
        train = SPLITS[TRAIN_SPLIT]
        raise TrainingError(
            f"--seeds {spec!r}: seed {outside[0]} is not in the {TRAIN_SPLIT} split "
            f"({train.start}-{train.stop - 1}; {describe_splits()}): figures are made on "
            "the others, so nothing is fitted on them")
    return seeds


def demo_scenario_names() -> set[str]:
    """The demo's scenarios (tools/sim/scenarios): never trained on."""
    from aeb_radar_camera.tools.sim.scenario import all_scenarios

    return {p.stem for p in all_scenarios()}


def seed_ranges(seeds: Sequence[int]) -> list[list[int]]:
    """[[first, last], ...] of sorted seeds: a compact record of many seeds."""
    out: list[list[int]] = []
    for s in sorted(set(seeds)):
        if out and s == out[-1][1] + 1:
            out[-1][1] = s
        else:
            out.append([s, s])
    return out


def features(records: list[RoiRecord], window: tuple[int, int], context: float
             ) -> tuple[np.ndarray, list[int]]:
    """(descriptors (n, d), indices of the records they belong to); records whose frame
    cannot be rebuilt are reported on stderr and left out."""
    by_frame: dict[FrameRef, list[int]] = defaultdict(list)
    for i, r in enumerate(records):
        by_frame[r.frame_ref].append(i)
    rows, kept = [], []
    for n, idx in enumerate(by_frame.values(), 1):
        first = records[idx[0]]
        try:
            gray = load_gray(first.frame_ref)
        except FrameLoadError as exc:
            print(f"frame {first.frame_key} left out: {exc}", file=sys.stderr)
            continue
        for i in idx:
            r = records[i]
            obs = Observation(gray, Roi(*r.roi), Roi(*r.column), r.range_m)
            rows.append(hog_linear_features(obs, window, context))
            kept.append(i)
        if n % 20 == 0 or n == len(by_frame):
            print(f"\rfeatures: {n}/{len(by_frame)} frames, {len(kept)} ROIs", end="",
                  file=sys.stderr, flush=True)
    print(file=sys.stderr)
    if not rows:
        raise TrainingError("no ROI could be rebuilt from its frame")
    return np.vstack(rows).astype(np.float64), kept


def fit_logistic(x: np.ndarray, y: np.ndarray, l2: float, iterations: int = 30
                 ) -> tuple[np.ndarray, float]:
    """(coef, bias) of an L2-regularised logistic regression on standardised features,
    classes weighted equally, by Newton's method; returned for raw features. Raises
    TrainingError when a class is missing."""
    n_pos, n_neg = int(y.sum()), int(len(y) - y.sum())
    if n_pos == 0 or n_neg == 0:
        raise TrainingError(f"need both classes, got {n_pos} YES and {n_neg} NO")
    mean = x.mean(axis=0)
    std = x.std(axis=0) + 1e-6
    z = np.c_[(x - mean) / std, np.ones(len(x))]
    weight = np.where(y > 0, len(y) / (2.0 * n_pos), len(y) / (2.0 * n_neg))
    penalty = np.full(z.shape[1], l2)
    penalty[-1] = 0.0                               # the bias is not shrunk
    beta = np.zeros(z.shape[1])
    for _ in range(iterations):
        p = 1.0 / (1.0 + np.exp(-np.clip(z @ beta, -30, 30)))
        grad = z.T @ (weight * (p - y)) + penalty * beta
        hess = (z * (weight * p * (1 - p))[:, None]).T @ z + np.diag(penalty + 1e-9)
        step = np.linalg.solve(hess, grad)
        beta -= step
        if np.max(np.abs(step)) < 1e-6:
            break
    coef = beta[:-1] / std
    return coef, float(beta[-1] - coef @ mean)


def auc(scores: np.ndarray, y: np.ndarray) -> float:
    """Mann-Whitney AUC (ties a half)."""
    pos, neg = scores[y > 0], scores[y == 0]
    greater = (pos[:, None] > neg[None, :]).sum() + 0.5 * (pos[:, None] == neg[None, :]).sum()
    return float(greater / (len(pos) * len(neg)))


def out_of_fold(x: np.ndarray, y: np.ndarray, groups: list[str], l2: float, folds: int
                ) -> np.ndarray:
    """Each ROI's probability from a model trained on the other folds of frames
    (`groups`: each ROI's frame digest)."""
    fold = np.array([fold_of("cv:" + g, folds) for g in groups])
    out = np.full(len(y), np.nan)
    for k in range(folds):
        test = fold == k
        if test.all() or not test.any() or len(set(y[~test].tolist())) < 2:
            continue            # nothing to validate on, or a class missing to fit
        coef, bias = fit_logistic(x[~test], y[~test], l2)
        out[test] = 1.0 / (1.0 + np.exp(-(x[test] @ coef + bias)))
    return out


def tau_for_recall(scores: np.ndarray, y: np.ndarray, recall: float) -> float:
    """The highest threshold that passes at least `recall` of the positives."""
    pos = np.sort(scores[(y > 0) & np.isfinite(scores)])
    if len(pos) == 0:
        return 0.5
    k = int(np.floor((1.0 - recall) * len(pos) + 1e-9))
    return float(pos[min(k, len(pos) - 1)])


def parse_window(text: str) -> tuple[int, int]:
    """`WxH` in px, multiples of 8, at least 16. Raises TrainingError."""
    w, sep, h = text.lower().partition("x")
    if not sep:
        raise TrainingError(f"--window {text!r}: expected WxH, e.g. 32x64")
    try:
        out = int(w), int(h)
    except ValueError as exc:
        raise TrainingError(f"--window {text!r}: expected WxH, e.g. 32x64") from exc
    if min(out) < 16 or out[0] % 8 or out[1] % 8:
        raise TrainingError(f"--window {text}: multiples of 8, at least 16")
    return out


def _digests(records: list[RoiRecord]) -> tuple[list[RoiRecord], dict[str, str]]:
    """(the records whose frame has a content digest, id -> digest); a frame that
    cannot be read is reported and its records left out."""
    cache: dict[FrameRef, str] = {}
    kept, out = [], {}
    failed: set[FrameRef] = set()
    for r in records:
        if r.frame_ref in failed:
            continue
        try:
            out[r.id] = record_digest(r, cache)
        except FrameLoadError as exc:
            failed.add(r.frame_ref)
            print(f"frame {r.frame_key} left out: {exc}", file=sys.stderr)
            continue
        kept.append(r)
    return kept, out


def choose(records: list[RoiRecord], labels: dict[str, str], o: TrainOptions
           ) -> tuple[list[RoiRecord], dict[str, Any]]:
    """The labelled records to train on and what was chosen how (for `trained_on`):
    the seeds' cases only (with --seeds), never a demo scenario, outside the held-out
    fold. Raises TrainingError."""
    usable = [r for r in records if labels.get(r.id) in (labelfile.YES, labelfile.NO)]
    demo = demo_scenario_names()
    n_demo = sum(1 for r in usable if r.scenario in demo)
    if n_demo:
        print(f"{n_demo} ROIs of the demo's own scenarios left out (never trained on)",
              file=sys.stderr)
    usable = [r for r in usable if r.scenario not in demo]
    info: dict[str, Any] = {"demo_scenario_rois_left_out": n_demo}
    if o.seeds:
        wanted = set(training_seeds(o.seeds))
        seeded = [r for r in usable if case_seed(r.scenario) in wanted]
        print(f"seeds {o.seeds}: {len(seeded)} of {len(usable)} labelled ROIs are of "
              "those cases", file=sys.stderr)
        usable = seeded
        info["split"] = TRAIN_SPLIT
        info["seeds_asked"] = o.seeds
        info["seeds"] = seed_ranges([s for r in usable
                                     if (s := case_seed(r.scenario)) is not None])
    usable, digest = _digests(usable)
    held = [r for r in usable if o.folds > 1 and fold_of(digest[r.id], o.folds) == o.fold]
    held_digests = {digest[r.id] for r in held}
    chosen = [r for r in usable if digest[r.id] not in held_digests]
    if not chosen:
        raise TrainingError(f"no labelled ROI to train on in {o.rois}")
    print(f"training on {len(chosen)} labelled ROIs of "
          f"{len({digest[r.id] for r in chosen})} frames ({len(held)} ROIs of "
          f"{len(held_digests)} frames held out)", file=sys.stderr)
    info["digests"] = digest
    return chosen, info


def train(o: TrainOptions) -> HogLinearModel:
    """Raises TrainingError, RecordFileError, LabelFileError, OSError."""
    if o.folds < 1 or not 0 <= o.fold < o.folds:
        raise TrainingError(f"--fold {o.fold} of --folds {o.folds}")
    if not 0.0 < o.recall <= 1.0 or o.cv_folds < 2 or o.l2 <= 0:
        raise TrainingError("--recall in (0, 1], --cv-folds >= 2, --l2 > 0")
    records = read_records(o.rois)
    given = labelfile.read_labels(o.labels) if o.labels else None
    labels = labelfile.resolve(records, given)
    chosen, info = choose(records, labels, o)
    digest = info.pop("digests")
    x, kept = features(chosen, o.window, o.context)
    kept_records = [chosen[i] for i in kept]
    y = np.array([1.0 if labels[r.id] == labelfile.YES else 0.0 for r in kept_records])
    groups = [digest[r.id] for r in kept_records]
    oof = out_of_fold(x, y, groups, o.l2, o.cv_folds)
    tau = tau_for_recall(oof, y, o.recall)
    coef, bias = fit_logistic(x, y, o.l2)
    finite = np.isfinite(oof)
    cv_auc = auc(oof[finite], y[finite]) if finite.any() and 0 < y[finite].sum() < \
        finite.sum() else float("nan")
    kinds: dict[str, int] = defaultdict(int)
    for r in kept_records:
        kinds[r.kind] += 1
    scenarios = sorted({r.scenario for r in kept_records if r.scenario})
    trained_on = {
        "rois": str(Path(o.rois)), "labels": o.labels or "ground truth",
        "sources": sorted({r.source for r in kept_records}),
        "yes": int(y.sum()), "no": int(len(y) - y.sum()), "kinds": dict(kinds),
        "folds": o.folds, "held_out_fold": o.fold if o.folds > 1 else None,
        "fold_by": "frame content (sha256 of the decoded grey frame)",
        **info, "scenarios": scenarios,
        "l2": o.l2, "recall_target": o.recall, "cv_folds": o.cv_folds,
        "cv_auc": None if np.isnan(cv_auc) else cv_auc,
        "frames": sorted({r.frame_key for r in kept_records}),
        "frame_sha256": sorted(set(groups)),
    }
    print(f"{int(y.sum())} YES, {int(len(y) - y.sum())} NO; cross-validated AUC "
          f"{cv_auc:.3f}; tau {tau:.4f} keeps {o.recall:.0%} of the positives",
          file=sys.stderr)
    return HogLinearModel(o.window, o.context, coef.astype(np.float32), bias, tau,
                          trained_on)


def trained_digests(model: HogLinearModel, where: str) -> set[str]:
    """The content digests of the frames `model` was trained on. Raises ValueError for
    weights written without them (their frames are known only by path)."""
    digests = model.trained_on.get("frame_sha256")
    if not isinstance(digests, list):
        raise ValueError(f"{where}: its trained_on names no frame content (frame_sha256): "
                         "weights written before frames were known by content; train "
                         "them again with aeb train-verifier")
    return {str(d) for d in digests}
