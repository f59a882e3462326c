"""Evaluation throughput: `aeb eval` on a recording, ROIs per second per core, and the
projection for the paper's 131,603 frames on a machine like CI's (2 cores).

    python -m benchmarks.bench_eval [--quick] [--out out/bench]

The recording is written here in the project's MCAP layout from SIMULATED frames (the
simulator's renderer, a few scenes reused, JPEG at the camera's quality) at 30 fps, with
a radar cycle every 75 ms holding about one confirmed track in 3-25 m: 0.46 ROIs per
frame, the paper's ratio (60,492 ROIs from 131,603 frames).

Measured in the same run:
- baseline: reading the recording and decoding the JPEG of the frame of every radar
  cycle (what any evaluation of these frames pays at least);
- the evaluation task (`tools.eval.runner.run_task`: fusion's frame choice and
  projection, every registered verifier, full-frame timing) in this process;
- the same, one task per recording, over every core (spawned processes, start-up
  included).
The projection divides the paper's frames by the single-process rate times 2 cores.
Writes bench_eval.json under --out; `run(quick, out_dir)` returns the suite's figures.
"""

import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.imaging import decode_gray, encode_jpeg
from aeb_radar_camera.common.keys import CAMERA_INFO, CAMERA_JPEG, RADAR_TRACKS
from aeb_radar_camera.common.messages import (
    CameraInfo,
    CompressedFrame,
    Header,
    OutputMode,
    RadarTrack,
    RadarTracks,
    decode,
)
from aeb_radar_camera.tools.eval.recording import RecordingSettings
from aeb_radar_camera.tools.eval.runner import Task, execute, run_task
from aeb_radar_camera.tools.eval.scoring import default_specs
from aeb_radar_camera.tools.messages import ObjectKind
from aeb_radar_camera.tools.recording.reader import Recording
from aeb_radar_camera.tools.recording.writer import RecordingWriter
from aeb_radar_camera.tools.sim.scenes import Obstacle, Scene, render
from benchmarks.figures import Figure, section_main

CALIBRATION = "deploy/calibration/d435_848x480.toml"
PAPER_FRAMES = 131_603
PAPER_ROIS = 60_492
TARGET_MIN = 10.0
CI_CORES = 2
FRAME_NS = 33_333_333
RADAR_NS = 75_000_000
T0 = 1_800_000_000_000_000_000
# Tracks per radar cycle that give the paper's ROIs per frame at 30 fps and 75 ms cycles.
EXTRA_TRACK_EVERY = 30
SCENES = ((8.0, 0.3, ObjectKind.PEDESTRIAN), (12.0, -0.5, ObjectKind.CAR),
          (18.0, 0.0, ObjectKind.BOX), (23.0, 1.0, ObjectKind.BICYCLE))


def _track(tid: int, x: float, y: float) -> RadarTrack:
    r = float(np.hypot(x, y))
    return RadarTrack(track_id=tid, x_m=x, y_m=y, vx_mps=-3.0, vy_mps=0.0, range_m=r,
                      range_rate_mps=-3.0 * x / r, rcs_dbsm=5.0, confirmed=True, hits=9,
                      misses=0, x_var_m2=0.1, y_var_m2=0.1)


def write_recording(path: Path, n_frames: int) -> dict[str, int]:
    """A SIMULATED recording of `n_frames` frames; returns its counts."""
    cal = Calibration.load(CALIBRATION)
    jpegs = [encode_jpeg(render(cal, Scene((Obstacle(x, y, kind),), seed=i)), 80)
             for i, (x, y, kind) in enumerate(SCENES)]
    per_scene = max(1, n_frames // len(SCENES))
    cycles = 0
    with RecordingWriter(path) as w:
        info = CameraInfo(header=Header(0, "camera/front", T0, 0), camera="front",
                          width=cal.width, height=cal.height, k=tuple(cal.k.ravel().tolist()),
                          dist=tuple(cal.dist.ravel().tolist()),
                          r=tuple(cal.r.ravel().tolist()), t_m=tuple(cal.t.ravel().tolist()),
                          fps=30.0, source="synthetic", frames_published=0, frames_dropped=0,
                          read_errors=0, healthy=True, status="")
        w.write_message(CAMERA_INFO.key("ego", camera="front"), info, T0)
        for i in range(n_frames):
            t = T0 + i * FRAME_NS
            msg = CompressedFrame(header=Header(i, "camera/front", t, 0), camera="front",
                                  width=cal.width, height=cal.height,
                                  jpeg=jpegs[(i // per_scene) % len(jpegs)])
            w.write_message(CAMERA_JPEG.key("ego", camera="front"), msg, t + 4_000_000)
        end = T0 + n_frames * FRAME_NS
        t = T0 + 20_000_000
        while t < end:
            x, y, _ = SCENES[((t - T0) // FRAME_NS // per_scene) % len(SCENES)]
            tracks = [_track(1, x, y)]
            if cycles % EXTRA_TRACK_EVERY == 0:
                tracks.append(_track(2, x + 3.0, y - 2.0))
            w.write_message(RADAR_TRACKS.key("ego", sensor="front"),
                    RadarTracks(header=Header(cycles, "radar/front", t, 0), sensor="front",
                                mode=OutputMode.OBJECTS, meas_counter=cycles, complete=True,
                                n_detections=len(tracks), n_prefiltered=len(tracks),
                                last_frame_mono_ns=0, processing_ns=0, tracks=tuple(tracks)),
                    t + 2_000_000)
            cycles += 1
            t += RADAR_NS
    return {"frames": n_frames, "cycles": cycles}


def read_and_decode(path: Path) -> tuple[float, int]:
    """Baseline: read every message, decode the newest frame at each radar cycle."""
    t0 = time.perf_counter()
    latest = b""
    decoded = 0
    topics = ["aeb/ego/camera/front/jpeg", "aeb/ego/radar/front/tracks"]
    for m in Recording.open(path).records(topics):
        if m.schema_name == "aeb.CompressedFrame":
            latest = m.data
        elif latest:
            decode_gray(decode(latest, CompressedFrame).jpeg)
            decoded += 1
    return time.perf_counter() - t0, decoded


def run(quick: bool, out_dir: Path) -> list[Figure]:
    """Measure, print, write bench_eval.json; the suite's figures."""
    n_frames = 450 if quick else 1800
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "bench_eval_recording.mcap"
    counts = write_recording(path, n_frames)
    specs = tuple(default_specs())
    settings = RecordingSettings()
    run_task(Task("recording", str(path), specs, recording=settings))   # warm the caches
    base_s, decoded = read_and_decode(path)
    one = run_task(Task("recording", str(path), specs, recording=settings))
    if one.errors:
        raise RuntimeError(f"evaluation failed: {one.errors}")
    cores = os.cpu_count() or 1
    t0 = time.perf_counter()
    many = execute([Task("recording", str(path), specs, recording=settings)] * cores,
                   jobs=cores)
    many_s = time.perf_counter() - t0
    rois = len(one.records)
    per_frame_ms = one.seconds / n_frames * 1000
    base_ms = base_s / n_frames * 1000
    rois_per_s = rois / one.seconds
    many_rois_per_s = sum(len(r.records) for r in many) / many_s
    projected_min = PAPER_FRAMES * per_frame_ms / 1000 / CI_CORES / 60
    base_min = PAPER_FRAMES * base_ms / 1000 / CI_CORES / 60
    result: dict[str, Any] = {
        **counts, "rois": rois, "rois_per_frame": rois / n_frames, "decoded_baseline": decoded,
        "verifiers": [s.label for s in specs], "task_s": one.seconds, "baseline_s": base_s,
        "ms_per_frame": per_frame_ms, "baseline_ms_per_frame": base_ms,
        "rois_per_s_per_core": rois_per_s, "processes": cores, "parallel_s": many_s,
        "parallel_rois_per_s": many_rois_per_s,
        "projected_paper_min_on_2_cores": projected_min,
        "baseline_paper_min_on_2_cores": base_min}
    (out_dir / "bench_eval.json").write_text(json.dumps(result, indent=2))
    print(f"recording: {n_frames} frames, {counts['cycles']} radar cycles, {rois} ROIs "
          f"({rois / n_frames:.2f} per frame; the paper {PAPER_ROIS / PAPER_FRAMES:.2f}), "
          f"verifiers {', '.join(result['verifiers'])}")
    print(f"baseline (read + JPEG decode of each cycle's frame): {base_ms:.2f} ms per frame")
    print(f"aeb eval task, 1 process: {per_frame_ms:.2f} ms per frame, "
          f"{rois_per_s:.0f} ROIs/s per core")
    print(f"{cores} processes, one task each (spawn included): {many_rois_per_s:.0f} ROIs/s "
          f"in {many_s:.1f} s")
    print(f"the paper's {PAPER_FRAMES:,} frames on {CI_CORES} cores: {projected_min:.1f} min "
          f"projected (baseline {base_min:.1f} min; target < {TARGET_MIN:.0f} min)")
    print(f"wrote {out_dir / 'bench_eval.json'}")
    return [
        Figure("eval", "ms per recorded frame, 1 process", per_frame_ms, "ms",
               "read + JPEG decode only", base_ms,
               note=f"{rois / n_frames:.2f} ROIs/frame, {len(specs)} verifiers"),
        Figure("eval", "ROIs/s per core", rois_per_s, "ROI/s",
               f"{cores} processes (per core)", many_rois_per_s / cores),
        Figure("eval", f"paper's {PAPER_FRAMES:,} frames on {CI_CORES} cores, projected",
               projected_min, "min", "read + decode only, projected", base_min,
               target=f"< {TARGET_MIN:.0f} min", target_met=projected_min < TARGET_MIN),
    ]


def main(argv: list[str] | None = None) -> int:
    return section_main("bench_eval", __doc__, run, argv, "a 15 s recording")


if __name__ == "__main__":
    raise SystemExit(main())
