"""What `aeb eval` (tools/eval/cli.py) runs once its arguments are read: ROIs from the
sources, the report and comparison of a ROI set, the held-out selection by frame content,
the paper's constructed tables and the demo recording."""

import argparse
import json
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import ConfigError, load_config, parse_config
from aeb_radar_camera.common.depth_error import D435Noise
from aeb_radar_camera.services.fusion.verifiers import VerifierConfigError
from aeb_radar_camera.tools.eval import labels as labelfile
from aeb_radar_camera.tools.eval import plots, tables
from aeb_radar_camera.tools.eval.dataset_rois import DatasetSettings
from aeb_radar_camera.tools.eval.frames import FrameLoadError, record_digest
from aeb_radar_camera.tools.eval.labels import LabelFileError
from aeb_radar_camera.tools.eval.recording import RecordingSettings
from aeb_radar_camera.tools.eval.records import (
    ROIS_FILE,
    RUN_FILE,
    SCORES_VERIFIER,
    FrameRef,
    RecordFileError,
    RoiRecord,
    RunInfo,
    read_records,
    records_from_scores,
    write_records,
    write_run,
)
from aeb_radar_camera.tools.eval.report import ReportSettings, evaluate_all
from aeb_radar_camera.tools.eval.runner import Progress, SourceError, execute, plan
from aeb_radar_camera.tools.eval.scoring import VerifierSpec, default_specs, parse_spec
from aeb_radar_camera.tools.machine import machine_info


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
    taus = tuple(float(t) for t in args.taus.split(",") if t.strip()) or None
    return ReportSettings(taus=taus, tau=args.tau, ci_group=args.ci_group, n_boot=args.boot,
                          groups=tuple(groups),
                          structures_as_negatives=args.structures_as_negatives)


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
    """The records of frames that `weights` was not trained on, frames known by their
    content (frames.record_digest), never by path or name: the same pictures stored
    elsewhere are still training frames. A record whose frame cannot be read cannot be
    shown to be held out: left out, counted on stderr. Raises VerifierConfigError for a
    weights file that cannot be read, ValueError for one that names no frame content."""
    from aeb_radar_camera.services.fusion.verifiers.appearance import HogLinearModel
    from aeb_radar_camera.tools.eval.training import trained_digests

    trained = trained_digests(HogLinearModel.load(weights), weights)
    cache: dict[FrameRef, str] = {}
    failed: set[FrameRef] = set()
    kept, seen_trained = [], 0
    for r in records:
        if r.frame_ref in failed:
            continue
        try:
            digest = record_digest(r, cache)
        except FrameLoadError as exc:
            failed.add(r.frame_ref)
            print(f"warning: {r.frame_key} left out of the held-out set: its frame "
                  f"cannot be read to tell whether it was trained on ({exc})",
                  file=sys.stderr)
            continue
        if digest in trained:
            seen_trained += 1
        else:
            kept.append(r)
    print(f"held out of {weights}: {len(kept)} of {len(records)} ROIs "
          f"({len({r.frame_ref for r in kept})} frames); {seen_trained} ROIs are of "
          f"frames it was trained on" + (f", {len(failed)} frames unreadable" if failed
                                          else ""), file=sys.stderr)
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
        warned = tables.warnings_text(result)
        text = ((warned + "\n\n" if warned else "") + tables.compare_table(evs) + "\n\n"
                + tables.compare_kinds_table(evs) + "\n")
    else:
        text = tables.full_report(result, args.stratum)
    print(text)
    warned = tables.warnings_text(result)
    if warned:
        print(warned, file=sys.stderr)
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


def _paper(args: argparse.Namespace, main: Callable[[list[str]], int]) -> int:
    from aeb_radar_camera.tools.eval import paper
    from aeb_radar_camera.tools.eval.options import PAPER_SWEEP

    out = Path(args.out)
    labels, scores = paper.write(out)
    print(f"constructed label set {labels} and scores {scores} (the paper's counts; "
          "the scores are constructed, not measured)\n")
    argv = ["report", "--scores", str(scores), "--labels", str(labels), "--out", str(out),
            "--tau", "0.025", "--ci-group", "roi", "--stratum", "group",
            "--taus", ",".join(f"{t:.3f}" for t in PAPER_SWEEP)]
    for g in paper.group_args():
        argv += ["--group", g]
    return main(argv)


def run(args: argparse.Namespace, main: Callable[[list[str]], int]) -> int:
    """The command of `args`; `main` is aeb eval's own (`paper` runs a report through
    it). Bad arguments and unusable input are reported, never raised."""
    try:
        if args.command == "paper":
            return _paper(args, main)
        if args.command == "record-demo":
            from aeb_radar_camera.tools.eval.demo_recording import record_demo

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
