"""`aeb train-verifier`: train the `hog_linear` verifier on labelled ROIs of `aeb eval`.

    aeb eval rois ../shared/data/kitti-tiny --out out/eval/kitti
    aeb train-verifier out/eval/kitti --out out/hog/kitti-fold0.json --folds 2 --fold 0
    aeb eval run ../shared/data/kitti-tiny --out out/eval/kitti-hog \\
        --verifier hog_linear:weights=out/hog/kitti-fold0.json
    aeb eval compare out/eval/kitti-hog --held-out out/hog/kitti-fold0.json

The ROIs are those of a ROI folder (`rois.jsonl`), labelled by `--labels` (an `aeb label`
file) or else by their ground truth (`truth-labels.tsv`, data sets and simulator runs);
ambiguous ROIs are left out. Every frame is rebuilt from the record's `frame` reference
exactly as the verifiers saw it, and the window that `hog_linear` classifies is cut from
it by the verifier's own code. The classifier is an L2-regularised logistic regression
on the HOG descriptor, the classes weighted equally, fitted by Newton's method.

`--folds K --fold k` trains on the frames outside fold k (frames are given to folds by a
hash of session and frame), so that the figures of `aeb eval ... --held-out WEIGHTS` come
from frames the weights never saw. The threshold `tau` written with the weights is the
one that keeps `--recall` of the positives on held-out folds of the training frames
(cross-validated inside them). The weights file (JSON) says what it was trained on: the
ROI folder, label source, counts and every training frame. Weights trained on a data
set inherit its licence: KITTI's and View-of-Delft's may not be shipped.

Exit codes: 0 written, 2 bad arguments or no usable training data, 130 interrupted.
"""

import argparse
import sys
import zlib
from collections import defaultdict
from pathlib import Path

import numpy as np

from common.log import add_log_level, setup_logging
from services.fusion.appearance import HogLinearModel, hog_linear_features
from services.fusion.roi import Roi
from services.fusion.verifiers import Observation
from tools.eval import labels as labelfile
from tools.eval.frames import FrameLoadError, load_gray
from tools.eval.records import RecordFileError, RoiRecord, read_records


class TrainingError(ValueError):
    """Training data that cannot train a classifier; the message says why."""


def fold_of(key: str, folds: int) -> int:
    """The fold of a frame: stable across runs and machines (CRC-32 of its key)."""
    return zlib.crc32(key.encode()) % folds


def features(records: list[RoiRecord], window: tuple[int, int], context: float
             ) -> tuple[np.ndarray, list[int]]:
    """(descriptors (n, d), indices of the records they belong to); records whose frame
    cannot be rebuilt are reported on stderr and left out."""
    by_frame: dict[str, list[int]] = defaultdict(list)
    for i, r in enumerate(records):
        by_frame[r.frame_key].append(i)
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
    """Each ROI's probability from a model trained on the other folds of frames."""
    fold = np.array([fold_of("cv:" + g, folds) for g in groups])
    out = np.full(len(y), np.nan)
    for k in range(folds):
        test = fold == k
        if test.all() or not test.any():
            continue
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


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="aeb train-verifier", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    add_log_level(p, "INFO")
    p.add_argument("rois", help="a ROI folder of `aeb eval rois` (rois.jsonl) or file")
    p.add_argument("--out", required=True, help="the weights file to write (JSON)")
    p.add_argument("--labels", help="label file (default: the ROIs' ground truth)")
    p.add_argument("--folds", type=int, default=1,
                   help="split the frames into this many folds (default 1: train on all)")
    p.add_argument("--fold", type=int, default=0, help="the fold held out (not trained on)")
    p.add_argument("--recall", type=float, default=0.99,
                   help="tau keeps this share of the positives on held-out folds")
    p.add_argument("--cv-folds", type=int, default=4,
                   help="folds of the training frames that choose tau (default 4)")
    p.add_argument("--l2", type=float, default=300.0, help="L2 penalty (default 300)")
    p.add_argument("--window", default="32x64", help="HOG window WxH px (multiples of 8)")
    p.add_argument("--context", type=float, default=1.25,
                   help="the window's height over the column's (default 1.25)")
    return p.parse_args(argv)


def _window(text: str) -> tuple[int, int]:
    w, sep, h = text.lower().partition("x")
    if not sep:
        raise TrainingError(f"--window {text!r}: expected WxH, e.g. 32x64")
    out = int(w), int(h)
    if min(out) < 16 or out[0] % 8 or out[1] % 8:
        raise TrainingError(f"--window {text}: multiples of 8, at least 16")
    return out


def train(args: argparse.Namespace) -> HogLinearModel:
    """Raises TrainingError, RecordFileError, LabelFileError, OSError."""
    if args.folds < 1 or not 0 <= args.fold < args.folds:
        raise TrainingError(f"--fold {args.fold} of --folds {args.folds}")
    if not 0.0 < args.recall <= 1.0 or args.cv_folds < 2 or args.l2 <= 0:
        raise TrainingError("--recall in (0, 1], --cv-folds >= 2, --l2 > 0")
    window = _window(args.window)
    records = read_records(args.rois)
    given = labelfile.read_labels(args.labels) if args.labels else None
    labels = labelfile.resolve(records, given)
    usable = [r for r in records if labels.get(r.id) in (labelfile.YES, labelfile.NO)]
    held = [r for r in usable if args.folds > 1 and fold_of(r.frame_key, args.folds)
            == args.fold]
    held_keys = {r.frame_key for r in held}
    chosen = [r for r in usable if r.frame_key not in held_keys]
    if not chosen:
        raise TrainingError(f"no labelled ROI to train on in {args.rois}")
    print(f"training on {len(chosen)} labelled ROIs of "
          f"{len({r.frame_key for r in chosen})} frames ({len(held)} ROIs of "
          f"{len(held_keys)} frames held out)", file=sys.stderr)
    x, kept = features(chosen, window, args.context)
    kept_records = [chosen[i] for i in kept]
    y = np.array([1.0 if labels[r.id] == labelfile.YES else 0.0 for r in kept_records])
    groups = [r.frame_key for r in kept_records]
    oof = out_of_fold(x, y, groups, args.l2, args.cv_folds)
    tau = tau_for_recall(oof, y, args.recall)
    coef, bias = fit_logistic(x, y, args.l2)
    finite = np.isfinite(oof)
    cv_auc = auc(oof[finite], y[finite]) if finite.any() else float("nan")
    kinds: dict[str, int] = defaultdict(int)
    for r in kept_records:
        kinds[r.kind] += 1
    trained_on = {
        "rois": str(Path(args.rois)), "labels": args.labels or "ground truth",
        "sources": sorted({r.source for r in kept_records}),
        "yes": int(y.sum()), "no": int(len(y) - y.sum()), "kinds": dict(kinds),
        "folds": args.folds, "held_out_fold": args.fold if args.folds > 1 else None,
        "l2": args.l2, "recall_target": args.recall, "cv_folds": args.cv_folds,
        "cv_auc": cv_auc, "frames": sorted(set(groups)),
    }
    print(f"{int(y.sum())} YES, {int(len(y) - y.sum())} NO; cross-validated AUC "
          f"{cv_auc:.3f}; tau {tau:.4f} keeps {args.recall:.0%} of the positives",
          file=sys.stderr)
    return HogLinearModel(window, args.context, coef.astype(np.float32), bias, tau,
                          trained_on)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging(args.log_level)
    try:
        model = train(args)
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        model.save(out)
    except KeyboardInterrupt:
        return 130
    except (TrainingError, RecordFileError, labelfile.LabelFileError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
