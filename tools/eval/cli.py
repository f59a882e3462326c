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
import json
import os
import signal
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from common.config.fusion import FusionConfig
from common.config.loader import ConfigError, load_config, parse_config
from common.depth_error import D435Noise
from common.log import add_log_level, setup_logging
from services.fusion.verifiers import VerifierConfigError
from tools.eval import labels as labelfile
from tools.eval import plots, tables
from tools.eval.dataset_rois import DEPTH_MODES, DatasetSettings
from tools.eval.labels import LabelFileError
from tools.eval.recording import RecordingSettings
from tools.eval.records import (
    ROIS_FILE,
    RUN_FILE,
    SCORES_VERIFIER,
    RecordFileError,
    RoiRecord,
    RunInfo,
    read_records,
    records_from_scores,
    write_records,
    write_run,
)
from tools.eval.report import PAPER_SWEEP, ReportSettings, evaluate_all
from tools.eval.runner import FRAMES_PER_TASK, Progress, SourceError, execute, plan
from tools.eval.scoring import VerifierSpec, default_specs, parse_spec
from tools.machine import machine_info


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
    p.add_argument("--taus", default=",".join(f"{t:.3f}" for t in PAPER_SWEEP),
                   help="thresholds of the sweep (Table IV)")
    p.add_argument("--group", action="append", default=[], metavar="NAME=GLOB",
                   help="a session group for Table V (repeatable, in order)")
    p.add_argument("--stratum", help="Table V by this stratum only (group, lighting, "
                                     "range, class, kind, camera)")
    p.add_argument("--ci-group", choices=["frame", "session", "roi"], default="frame",
                   help="bootstrap resamples whole frames, sessions or single ROIs")
    p.add_argument("--boot", type=int, default=2000, help="bootstrap samples")
    p.add_argument("--no-plots", action="store_true")
    p.add_argument("--held-out", metavar="WEIGHTS",
                   help="only the ROIs of frames these hog_linear weights were not trained "
                        "on (the weights file's trained_on.frames)")


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


def _calibrations(items: list[str], cameras: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        name, eq, path = item.partition("=")
        if eq:
            out[name] = path
        else:
            out.update({c: item for c in cameras})
    return out


def _extract(args: argparse.Namespace) -> tuple[list[RoiRecord], RunInfo, int]:
    """Raises ConfigError, VerifierConfigError, SourceError for bad arguments."""
    left_out: dict[str, str] = {}
    specs: list[VerifierSpec] = ([parse_spec(v) for v in args.verifier] if args.verifier
                                 else default_specs(left_out))
    cfg = (load_config(args.fusion_config, FusionConfig) if args.fusion_config
           else parse_config({}, FusionConfig))
    fusion = cfg.fusion
    recording = RecordingSettings(
        fusion=fusion,
        calibrations=_calibrations(args.calibration, [c.name for c in fusion.camera_inputs]),
        prefer_config_calibration=args.config_calibration or bool(args.fusion_config),
        background_per_object=args.background, timing=not args.no_timing, seed=args.seed)
    base = DatasetSettings()
    dataset = DatasetSettings(
        paper=replace(base.paper, focal_px=args.focal_px, column_width_m=args.column_width_m,
                      padding_px=args.padding_px, background_per_object=args.background),
        jpeg_quality=args.jpeg_quality, depth=args.depth,
        noise=D435Noise(focal_px=args.focal_px), timing=not args.no_timing, seed=args.seed)
    tasks = plan(args.sources, specs, recording, dataset, args.frames_per_task,
                 args.limit_frames)
    where = args.scheduler or f"{min(args.jobs, len(tasks))} local processes"
    print(f"{len(tasks)} tasks on {where}; verifiers: "
          f"{', '.join(s.label for s in specs)}", file=sys.stderr, flush=True)
    for name, why in left_out.items():
        print(f"verifier {name} left out ({why}): name it with --verifier",
              file=sys.stderr, flush=True)
    t0 = time.monotonic()
    progress = Progress(len(tasks))
    results = execute(tasks, args.jobs, args.scheduler, progress.update)
    seconds = time.monotonic() - t0
    records = [r for res in results for r in res.records]
    counters: dict[str, int] = {}
    errors: list[str] = []
    params: dict[str, dict[str, Any]] = {}
    for res in results:
        for k, v in res.counters.items():
            counters[k] = counters.get(k, 0) + v
        errors += res.errors
        params.update(res.params)
    info = RunInfo(sources=list(args.sources), verifiers=params or {
        s.label: dict(s.params) for s in specs},
        settings={"fusion_config": args.fusion_config or "(defaults)",
                  "focal_px": args.focal_px, "column_width_m": args.column_width_m,
                  "padding_px": args.padding_px, "jpeg_quality": args.jpeg_quality,
                  "depth": args.depth, "background_per_object": args.background,
                  "seed": args.seed},
        counters=counters, errors=errors, seconds=round(seconds, 2),
        workers=1 if args.scheduler else min(args.jobs, len(tasks)),
        scheduler=args.scheduler or "local", machine=machine_info())
    failed = sum(1 for res in results if res.counters.get("task_failed"))
    return records, info, failed


def _write_set(out: Path, records: list[RoiRecord], info: RunInfo) -> None:
    write_records(out / ROIS_FILE, records)
    write_run(out / RUN_FILE, info)
    truth = labelfile.truth_labels(records, "ground-truth")
    if truth:
        labelfile.write_labels(out / "truth-labels.tsv", truth)


def _summary(records: list[RoiRecord], info: RunInfo, out: Path) -> None:
    kinds: dict[str, int] = {}
    for r in records:
        kinds[r.kind] = kinds.get(r.kind, 0) + 1
    per_s = len(records) / info.seconds if info.seconds > 0 else 0.0
    print(f"{len(records)} ROIs ({', '.join(f'{k} {n}' for k, n in sorted(kinds.items()))})"
          f" in {info.seconds:.1f} s ({per_s:.0f} ROIs/s, {info.workers} workers); "
          f"written to {out / ROIS_FILE}")
    if info.counters:
        print("counters: " + ", ".join(f"{k} {v}" for k, v in sorted(info.counters.items())))
    for e in info.errors[:20]:
        print(f"error: {e}", file=sys.stderr)


def _report_settings(args: argparse.Namespace) -> ReportSettings:
    groups = []
    for g in args.group:
        name, eq, pattern = g.rpartition("=")
        if not eq or not name:
            raise ValueError(f"--group {g!r}: expected NAME=GLOB")
        groups.append((name, pattern))
    taus = tuple(float(t) for t in args.taus.split(",") if t.strip())
    return ReportSettings(taus=taus, tau=args.tau, ci_group=args.ci_group, n_boot=args.boot,
                          groups=tuple(groups))


def _load(args: argparse.Namespace) -> tuple[list[RoiRecord], dict[str, dict[str, Any]], Path]:
    if args.scores:
        tau = args.tau if args.tau is not None else 0.025
        records = records_from_scores(args.scores, tau)
        return records, {SCORES_VERIFIER: {"tau": tau}}, Path(args.out or
                                                              Path(args.scores).parent)
    if not args.rois:
        raise ValueError("give a ROI folder or --scores")
    src = Path(args.rois)
    records = read_records(src)
    folder = src if src.is_dir() else src.parent
    run_file = folder / RUN_FILE
    params: dict[str, dict[str, Any]] = {}
    if run_file.is_file():
        params = json.loads(run_file.read_text()).get("verifiers", {})
    if not params:
        params = {k: {} for r in records[:1] for k in r.scores}
    return records, params, Path(args.out) if args.out else folder


def held_out(records: list[RoiRecord], weights: str) -> list[RoiRecord]:
    """The records of frames that `weights` was not trained on. Raises
    VerifierConfigError for a weights file that cannot be read."""
    from services.fusion.appearance import HogLinearModel

    trained = set(HogLinearModel.load(weights).trained_on.get("frames", []))
    kept = [r for r in records if r.frame_key not in trained]
    print(f"held out of {weights}: {len(kept)} of {len(records)} ROIs "
          f"({len({r.frame_key for r in kept})} frames)", file=sys.stderr)
    return kept


def _report(args: argparse.Namespace, records: list[RoiRecord],
            params: dict[str, dict[str, Any]], out: Path, compare: bool) -> int:
    settings = _report_settings(args)
    if args.held_out:
        records = held_out(records, args.held_out)
    given = labelfile.read_labels(args.labels) if args.labels else None
    labels = labelfile.resolve(records, given)
    chosen = {k: v for k, v in params.items() if not args.only or k in args.only}
    if not chosen:
        raise ValueError(f"no verifier to report; the ROIs have {sorted(params)}")
    result = evaluate_all(records, labels, chosen, settings)
    if not result["verifiers"]:
        print("error: nothing to evaluate: "
              + "; ".join(f"{k}: {v}" for k, v in result["skipped"].items()), file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    name = "compare" if compare else "report"
    if compare:
        evs = list(result["verifiers"].values())
        text = tables.compare_table(evs) + "\n\n" + tables.compare_kinds_table(evs) + "\n"
    else:
        text = tables.full_report(result, args.stratum)
    print(text)
    (out / f"{name}.md").write_text(text)
    (out / f"{name}.json").write_text(json.dumps(result, indent=1))
    written = [out / f"{name}.md", out / f"{name}.json"]
    if not args.no_plots:
        written.append(plots.roc_plot(result, out / "roc.png", str(out)))
        written.append(plots.confusion_plot(result, out / "confusion.png"))
        first = next(iter(result["verifiers"]))
        written.append(plots.density_plot(records, labels, out / "density.png", first))
        if any(r.frame_canny_us is not None for r in records):
            written.append(plots.timing_plot(records, out / "timing.png"))
    print("wrote " + ", ".join(str(p) for p in written))
    return 0


def _paper(args: argparse.Namespace) -> int:
    from tools.eval import paper

    out = Path(args.out)
    labels, scores = paper.write(out)
    print(f"constructed label set {labels} and scores {scores} (the paper's counts; "
          "the scores are constructed, not measured)\n")
    argv = ["report", "--scores", str(scores), "--labels", str(labels), "--out", str(out),
            "--tau", "0.025", "--ci-group", "roi", "--stratum", "group"]
    for g in paper.group_args():
        argv += ["--group", g]
    return main(argv)


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging("eval", args.log_level)
    if threading.current_thread() is threading.main_thread():
        # SIGTERM stops like Ctrl-C: the worker processes are stopped, not left behind.
        signal.signal(signal.SIGTERM, _interrupt)
    try:
        if args.command == "paper":
            return _paper(args)
        if args.command == "record-demo":
            from tools.eval.demo_recording import record_demo

            return record_demo(Path(args.out), args.scenarios, args.camera_fps,
                               Path(args.fusion_config) if args.fusion_config else None)
        if args.command in ("rois", "run"):
            records, info, failed = _extract(args)
            out = Path(args.out)
            _write_set(out, records, info)
            _summary(records, info, out)
            if not records:
                print("error: no ROI from any source", file=sys.stderr)
                return 2
            if args.command == "rois":
                return 1 if failed else 0
            code = _report(args, records, info.verifiers, out, compare=False)
            return code or (1 if failed else 0)
        records, params, out = _load(args)
        return _report(args, records, params, out, compare=args.command == "compare")
    except (ConfigError, VerifierConfigError, SourceError, RecordFileError, LabelFileError,
            ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\ninterrupted: nothing written for the unfinished step", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
