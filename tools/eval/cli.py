"""`aeb eval`: the paper's evaluation (Tables II-V, Fig. 4) on recordings and public data
sets, for every verifier of fusion's registry on the same ROIs.

    aeb eval rois RECORDING.mcap [MORE ...] --out out/eval/drive   # dump ROIs + scores
    aeb label out/eval/drive --labels out/eval/drive/labels.tsv    # label them (web page)
    aeb eval report out/eval/drive --labels out/eval/drive/labels.tsv
    aeb eval compare out/eval/drive --labels out/eval/drive/labels.tsv
    aeb eval run ../shared/data/kitti-tiny --out out/eval/kitti     # rois + report
    aeb eval run ../shared/data/kitti-tiny --depth d435 --out out/eval/kitti-d435
    aeb eval record-demo --out out/eval/demo.mcap                   # simulator recording
    aeb eval paper --out out/eval/paper                             # Tables III-V exactly

Sources: MCAP recordings in the project's layout (files or folders of them), KITTI
object folders (image_2, label_2, calib, velodyne) and View-of-Delft roots. Recordings
use the fusion configuration's ROI geometry and frame alignment (--fusion-config);
data sets get the paper's construction at its pixel scale (--focal-px). Data sets and
simulator recordings are labelled by their ground truth; other recordings by `aeb label`.

Exit codes: 0 done, 1 some source failed (the others are evaluated), 2 bad arguments or
no usable input, 130 interrupted (SIGINT, SIGTERM).
"""

import argparse
import os
import signal
import sys
import threading

from aeb_radar_camera.common.log import add_log_level, setup_logging
from aeb_radar_camera.tools.eval.options import DEPTH_MODES, FRAMES_PER_TASK


def _add_extract(p: argparse.ArgumentParser) -> None:
    p.add_argument("sources", nargs="+", help="recordings (.mcap, or folders of them), "
                                              "KITTI or View-of-Delft folders")
    p.add_argument("--out", required=True, help="folder for rois.jsonl, run.json, tables")
    p.add_argument("--verifier", action="append", default=[], metavar="NAME[:K=V,...]",
                   help="a verifier to score (repeatable; default: every registered one)")
    p.add_argument("--fusion-config", help="fusion TOML: ROI geometry, frame alignment, "
                                           "range, cameras (recordings)")
    p.add_argument("--calibration", action="append", default=[], metavar="[CAMERA=]FILE",
                   help="calibration TOML for a camera of the recordings (default: the "
                        "--fusion-config's files, else the recorded CameraInfo)")
    p.add_argument("--config-calibration", action="store_true",
                   help="without --fusion-config: the default fusion config's calibration "
                        "files instead of the recorded CameraInfo")
    p.add_argument("--focal-px", type=float, default=449.0,
                   help="data sets: resample images to this focal length (the paper's "
                        "D435 at 848x480, default 449)")
    p.add_argument("--column-width-m", type=float, default=1.08,
                   help="data sets: width of the paper's column (default 1.08)")
    p.add_argument("--padding-px", type=int, default=22, help="data sets: ROI padding")
    p.add_argument("--jpeg-quality", type=int, default=80,
                   help="data sets: JPEG-code frames at this quality as the camera would "
                        "(0: no JPEG)")
    p.add_argument("--depth", choices=DEPTH_MODES, default="lidar",
                   help="data sets: depth for verifiers that use it - projected lidar, "
                        "lidar with the D435 noise model (d435), or none")
    p.add_argument("--background", type=int, default=2,
                   help="background negatives per positive (data sets, simulator runs)")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                   help="parallel processes (default: every core)")
    p.add_argument("--scheduler", default="",
                   help="a Dask scheduler (tcp://host:port) instead of local processes")
    p.add_argument("--frames-per-task", type=int, default=FRAMES_PER_TASK)
    p.add_argument("--limit-frames", type=int, default=0,
                   help="data sets: only the first N frames")
    p.add_argument("--no-timing", action="store_true", help="skip full-frame timing")
    p.add_argument("--seed", type=int, default=0)


def _add_report(p: argparse.ArgumentParser, sources: bool = True) -> None:
    if sources:
        p.add_argument("rois", nargs="?", help="a ROI folder (rois.jsonl) or file")
        p.add_argument("--scores", help="a CSV of scores (id,score[,session]) instead")
        p.add_argument("--out", help="where tables and plots go (default: the ROI folder)")
    p.add_argument("--labels", help="label file (default: ground truth where there is)")
    p.add_argument("--only", action="append", default=[], metavar="VERIFIER",
                   help="report only these verifiers (labels as in rois.jsonl)")
    p.add_argument("--tau", type=float, help="deployed threshold of Table III (default: "
                                             "each verifier's own tau)")
    p.add_argument("--taus", default="",
                   help="thresholds of the sweep (Table IV), for every verifier (default: "
                        "each verifier's own score range: the paper's thresholds for edge "
                        "densities, else quantiles of its scores)")
    p.add_argument("--group", action="append", default=[], metavar="NAME=GLOB",
                   help="a session group for Table V (repeatable, in order)")
    p.add_argument("--stratum", help="Table V by this stratum only (group, lighting, "
                                     "range, class, kind, camera)")
    p.add_argument("--ci-group", choices=["frame", "session", "roi"], default="frame",
                   help="bootstrap resamples whole frames, sessions or single ROIs")
    p.add_argument("--boot", type=int, default=2000, help="bootstrap samples")
    p.add_argument("--structures-as-negatives", action="store_true",
                   help="count real structures (lidar structure, radar returns on no "
                        "labelled object, background with lidar standing at its range, a "
                        "guard rail) as negatives, i.e. as false passes "
                        "where they pass (default: reported apart)")
    p.add_argument("--no-plots", action="store_true")
    p.add_argument("--held-out", metavar="WEIGHTS",
                   help="only the ROIs of frames these hog_linear weights were not trained "
                        "on: frames known by content (the weights file's "
                        "trained_on.frame_sha256), wherever they are stored")


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb eval", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_log_level(parser, "INFO")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_extract(sub.add_parser("rois", help="ROIs and every verifier's scores"))
    run = sub.add_parser("run", help="rois, then report")
    _add_extract(run)
    _add_report(run, sources=False)
    _add_report(sub.add_parser("report", help="tables and plots of a ROI set"))
    _add_report(sub.add_parser("compare", help="verifiers side by side on the same ROIs"))
    paper = sub.add_parser("paper", help="the paper's Tables III-V from a constructed set")
    paper.add_argument("--out", default="out/eval/paper")
    demo = sub.add_parser("record-demo", help="record the demo scenarios (simulation)")
    demo.add_argument("--out", default="out/eval/demo.mcap")
    demo.add_argument("--scenarios", default="", help="comma-separated (default: the "
                                                      "demo's)")
    demo.add_argument("--camera-fps", type=float, default=30.0)
    demo.add_argument("--fusion-config", help="fusion TOML of the closed loop (default: "
                                             "the demo's, deploy/fusion.toml)")
    return parser.parse_args(argv)


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging("eval", args.log_level)
    if threading.current_thread() is threading.main_thread():
        # SIGTERM stops like Ctrl-C: the worker processes are stopped, not left behind.
        signal.signal(signal.SIGTERM, _interrupt)
    # What runs the commands needs the eval extra; the options above do not (--help).
    from aeb_radar_camera.tools.eval import evaluate

    return evaluate.run(args, main)


if __name__ == "__main__":
    sys.exit(main())
