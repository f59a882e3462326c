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
hash of their content, the decoded picture, never by path or name), so that the figures
of `aeb eval ... --held-out WEIGHTS` come from frames the weights never saw, wherever
those frames are stored. `--seeds SPEC` (simulator recordings of generated cases,
tools/sim/families.py) trains only on the cases of those seeds, every one of them in the
`train` split (e.g. `--seeds train`, `--seeds 1000-1199`); the demo's own scenarios
(tools/sim/scenarios) are never trained on. The threshold `tau` written with the weights is the
one that keeps `--recall` of the positives on held-out folds of the training frames
(cross-validated inside them). The weights file (JSON) says what it was trained on: the
ROI folder, label source, counts, folds, seeds and scenarios, and every training frame
(by name and by content digest). Weights trained on a data
set inherit its licence: KITTI's and View-of-Delft's may not be shipped.

Exit codes: 0 written, 2 bad arguments or no usable training data, 130 interrupted.
"""

import argparse
import sys
from pathlib import Path
from typing import Any

from aeb_radar_camera.common.log import add_log_level, setup_logging


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
    p.add_argument("--seeds", default="", metavar="SPEC",
                   help="only the generated cases of these seeds, all in the train split: "
                        "train, train:N, A-B or a comma list (default: every ROI; "
                        "the demo's own scenarios never)")
    p.add_argument("--recall", type=float, default=0.99,
                   help="tau keeps this share of the positives on held-out folds")
    p.add_argument("--cv-folds", type=int, default=4,
                   help="folds of the training frames that choose tau (default 4)")
    p.add_argument("--l2", type=float, default=300.0, help="L2 penalty (default 300)")
    p.add_argument("--window", default="32x64", help="HOG window WxH px (multiples of 8)")
    p.add_argument("--context", type=float, default=1.25,
                   help="the window's height over the column's (default 1.25)")
    return p.parse_args(argv)


def __getattr__(name: str) -> Any:
    # The numeric core lives in tools/eval/training.py, imported on use so that --help
    # needs none of the eval extra; its names stay reachable from here.
    from aeb_radar_camera.tools.eval import training

    try:
        return getattr(training, name)
    except AttributeError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging("train-verifier", args.log_level)
    from aeb_radar_camera.tools.eval import labels as labelfile
    from aeb_radar_camera.tools.eval import training
    from aeb_radar_camera.tools.eval.records import RecordFileError

    try:
        options = training.TrainOptions(
            rois=args.rois, labels=args.labels, folds=args.folds, fold=args.fold,
            seeds=args.seeds, recall=args.recall, cv_folds=args.cv_folds, l2=args.l2,
            window=training.parse_window(args.window), context=args.context)
        model = training.train(options)
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        model.save(out)
    except KeyboardInterrupt:
        return 130
    except (training.TrainingError, RecordFileError, labelfile.LabelFileError,
            OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
