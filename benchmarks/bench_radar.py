"""Radar decode + tracking time per cycle (issue 2), and how it grows with clusters per
cycle (issue 6: 50, 250, 500).

Scenes are synthetic ARS408 transmissions built with the project's encoder: targets
moving at constant velocity with measurement noise. Object mode sends general + quality +
extended frames per object; cluster mode general + quality per cluster. `spread` scenes
put the targets over the radar's field (a third inside the 25 m prefilter window, 5
returns per target in cluster mode); the stress scenes put every detection, as an
independent target, inside the window: the worst case for merge and tracker.

Per-cycle figures are CPU time of the benchmark thread (`time.thread_time_ns`): what the
cycle costs, less disturbed by other processes taking the CPU than wall time (on a
shared machine wall-clock figures move by 2-3x with its load; thread time still moves by
up to 2x on a busy virtual machine, so compare rows of one run). Rows per scene, all
measured in this run:
- `pipeline`: every frame through `RadarCore.on_frame` (assembly, decode, prefilter,
  merge, Kalman tracker, messages): CPU time per cycle, and `after last frame`, the
  part spent once the cycle's last frame arrived (the latency share).
- `baseline scalar decode`: every frame of the cycle decoded into its record by the
  table's per-frame decoder (`ars408.decode`), nothing assembled or tracked: the
  figures' baseline, alternating with `pipeline` in blocks of 8 cycles so that both
  see the same machine.
- `baseline decode only`: assembly + the cycle decoder, no prefilter / merge / tracking.
- `baseline cantools`: the same frames through cantools and the exported DBC, when
  cantools is installed (it is not a dependency; `pip install cantools` to get the row).

A second table replays the real recording through the service shell (ReplayPort, no
CAN driver, no Zenoh) and reports `RadarTracks.processing_ns`, the time from the cycle's
last frame to its tracks message: paced in real time (the CPU idles 70 ms between
cycles, as in the vehicle) and, as the baseline, as fast as possible (caches warm).

Run: `python -m benchmarks.bench_radar [--quick] [--out out/bench]`; PNGs
radar_cycle_time.png and radar_cluster_scale.png under --out. The suite
(`python -m benchmarks`) calls `run(quick, out_dir)`: groups "radar" (object and cluster
mode per cycle, the 2 ms target) and "scale" (clusters 50 / 250 / 500).
"""

import argparse
import statistics
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aeb_radar_camera.common.config.radar import CanSettings, Pace, RadarSettings, ReplaySettings
from aeb_radar_camera.common.messages.radar import OutputMode, RadarStatus, RadarTracks
from aeb_radar_camera.common.resources import ARS408_RECORDING
from aeb_radar_camera.services.radar.ars408 import (
    ClusterGeneral,
    ClusterQuality,
    ObjectExtended,
    ObjectGeneral,
    ObjectQuality,
    RadarFrame,
    classify,
    cluster_cycle_frames,
    decode,
    object_cycle_frames,
)
from aeb_radar_camera.services.radar.ars408.table import MessageSpec
from aeb_radar_camera.services.radar.assembly import CycleAssembler, ListRole
from aeb_radar_camera.services.radar.core import RadarCore
from aeb_radar_camera.services.radar.detections import decode_cycle
from aeb_radar_camera.services.radar.shell import RadarShell
from aeb_radar_camera.tools.machine import machine_info
from benchmarks.figures import Figure

RECORDING = ARS408_RECORDING

TARGET_MS = 2.0
CPU_CLOCK = time.thread_time_ns
CYCLE_S = 0.075
Classified = list[tuple[MessageSpec, bytes]]


@dataclass(frozen=True)
class Scene:
    """`n` detections per cycle. `spread`: targets over the radar's field (x 1..80 m,
    |y| <= 15 m, about a third within the 25 m prefilter), each target returning
    `per_target` detections within +-0.6 m at one velocity (an extended object: what the
    merge is for). Otherwise the stress case: every detection an independent target
    inside the prefilter window (x 2..20 m, |y| <= 10 m), all of them tracked."""

    name: str
    mode: OutputMode
    n: int
    spread: bool = True
    per_target: int = 1


def scene_cycles(scene: Scene, cycles: int, seed: int = 1) -> list[Classified]:
    """`cycles` consecutive cycles of the scene, as classified frames."""
    rng = np.random.default_rng(seed)
    n_targets = -(-scene.n // scene.per_target)
    x_max, y_max = (80.0, 15.0) if scene.spread else (20.0, 10.0)
    x = rng.uniform(2.0, x_max, n_targets)
    y = rng.uniform(-y_max, y_max, n_targets)
    vx = rng.uniform(-12.0, 3.0, n_targets)
    vy = rng.uniform(-1.0, 1.0, n_targets)
    rcs = rng.uniform(-10.0, 30.0, n_targets)
    owner = np.arange(scene.n) % n_targets
    offset = rng.uniform(-0.6, 0.6, (scene.n, 2)) if scene.per_target > 1 else np.zeros(
        (scene.n, 2))
    out: list[Classified] = []
    for k in range(cycles):
        x = x + vx * CYCLE_S
        y = y + vy * CYCLE_S
        # Targets leaving the area re-enter at its far end: the count stays n.
        gone = (x < 1.0) | (x > x_max) | (np.abs(y) > y_max + 2)
        x[gone] = x_max - 1.0
        y[gone] = rng.uniform(-y_max, y_max, int(gone.sum()))
        mx = x[owner] + offset[:, 0] + rng.normal(0, 0.1, scene.n)
        my = y[owner] + offset[:, 1] + rng.normal(0, 0.1, scene.n)
        mvx = vx[owner] + rng.normal(0, 0.1, scene.n)
        mvy = vy[owner] + rng.normal(0, 0.1, scene.n)
        frames = _frames(scene.mode, k, mx, my, mvx, mvy, rcs[owner])
        out.append([(_spec(f), f.data) for f in frames])
    return out


def _spec(f: RadarFrame) -> MessageSpec:
    found = classify(f.arb_id)
    assert found is not None
    return found[0]


def _q(v: float, step: float) -> float:
    return round(v / step) * step


def _frames(mode: OutputMode, k: int, x: np.ndarray, y: np.ndarray, vx: np.ndarray,
            vy: np.ndarray, rcs: np.ndarray) -> list[RadarFrame]:
    rows = list(zip(x.tolist(), y.tolist(), vx.tolist(), vy.tolist(), rcs.tolist(),
                    strict=True))
    if mode is OutputMode.OBJECTS:
        objs = [ObjectGeneral(i, _q(a, .2), _q(b, .2), _q(c, .25), _q(d, .25), 0, _q(r, .5))
                for i, (a, b, c, d, r) in enumerate(rows)]
        qual = [ObjectQuality(i, 10, 12, 8, 14, 2, 6) for i in range(len(rows))]
        ext = [ObjectExtended(i, 0.0, 0.0, 1, 0.0, 4.0, 1.8) for i in range(len(rows))]
        return object_cycle_frames(objs, 2 * k, qual, ext)
    clusters = [ClusterGeneral(i % 256, _q(a, .2), _q(b, .2), _q(c, .25), _q(d, .25), 0,
                               _q(r, .5)) for i, (a, b, c, d, r) in enumerate(rows)]
    qual_c = [ClusterQuality(i % 256, 10, 12, 8, 14, 3, 3, 0) for i in range(len(rows))]
    near = min(len(rows), 255)
    return cluster_cycle_frames(clusters, k, qual_c, n_near=near)


@dataclass
class Result:
    scene: str
    method: str
    per_cycle_ms: list[float]
    after_last_ms: list[float] | None = None

    @property
    def median_ms(self) -> float:
        return statistics.median(self.per_cycle_ms)

    @property
    def p95_ms(self) -> float:
        return float(np.percentile(self.per_cycle_ms, 95))


def _feed_cycle(core: RadarCore, frames: Classified, t_s: float) -> tuple[float, float]:
    """One cycle's frames through `core`: (CPU ms for the cycle, CPU ms after its last
    frame)."""
    clock = CPU_CLOCK
    start = clock()
    for spec, data in frames[:-1]:
        core.on_frame(spec, data, t_s, 0, 0)
    last = clock()
    spec, data = frames[-1]
    results = core.on_frame(spec, data, t_s, 0, 0)
    end = clock()
    assert len(results) == 1 and results[0].complete, "benchmark cycle did not complete"
    return (end - start) / 1e6, (end - last) / 1e6


def run_pipeline(cycles: list[Classified]) -> tuple[list[float], list[float]]:
    """Per-cycle CPU ms and CPU ms after the last frame, every cycle through one core."""
    s = RadarSettings()
    core = RadarCore(s.sensors[0], s)
    per_cycle: list[float] = []
    after_last: list[float] = []
    for k, frames in enumerate(cycles):
        total, after = _feed_cycle(core, frames, k * CYCLE_S)
        per_cycle.append(total)
        after_last.append(after)
    return per_cycle, after_last


# Pipeline and baseline alternate in blocks of this many cycles: both see the same
# machine over the run, and neither runs right after the other's very different code.
PAIRED_BLOCK = 8


def run_paired(cycles: list[Classified]) -> tuple[Result, Result]:
    """The pipeline and the baseline (every frame decoded by the scalar decoder) on the
    same cycles, alternating in blocks of PAIRED_BLOCK cycles (which goes first
    alternates too)."""
    s = RadarSettings()
    core = RadarCore(s.sensors[0], s)
    times: tuple[list[float], list[float]] = ([], [])
    after: list[float] = []
    for b, start in enumerate(range(0, len(cycles), PAIRED_BLOCK)):
        block = range(start, min(start + PAIRED_BLOCK, len(cycles)))
        for which in ((0, 1) if b % 2 else (1, 0)):
            if which == 0:
                for k in block:
                    total, tail = _feed_cycle(core, cycles[k], k * CYCLE_S)
                    times[0].append(total)
                    after.append(tail)
            else:
                times[1].extend(run_per_frame([cycles[k] for k in block], decode))
    return (Result("", "pipeline", times[0], after),
            Result("", BASELINE, times[1]))


_ROLES = {"Obj_1_General": ListRole.GENERAL, "Obj_2_Quality": ListRole.QUALITY,
          "Obj_3_Extended": ListRole.EXTENDED, "Cluster_1_General": ListRole.GENERAL,
          "Cluster_2_Quality": ListRole.QUALITY}


def run_decode_only(cycles: list[Classified], mode: OutputMode) -> list[float]:
    asm = CycleAssembler(RadarSettings().cycle)
    out: list[float] = []
    for frames in cycles:
        start = CPU_CLOCK()
        status = decode(frames[0][0], frames[0][1])
        n = status[0] + (status[1] if mode is OutputMode.CLUSTERS else 0)
        done = asm.on_status(mode, n, status[-2], 0.0, 0, 0)
        for spec, data in frames[1:]:
            done += asm.on_list_frame(mode, _ROLES[spec.dbc_name], data, 0)
        for raw in done:
            decode_cycle(raw)
        out.append((CPU_CLOCK() - start) / 1e6)
    return out


def run_per_frame(cycles: list[Classified], decode_one: Callable[[MessageSpec, bytes], object]
                  ) -> list[float]:
    out: list[float] = []
    for frames in cycles:
        start = CPU_CLOCK()
        for spec, data in frames:
            decode_one(spec, data)
        out.append((CPU_CLOCK() - start) / 1e6)
    return out


def cantools_decoder() -> Callable[[MessageSpec, bytes], object] | None:
    try:
        import cantools
    except ImportError:
        return None
    from aeb_radar_camera.services.radar.ars408.dbc import DBC_PATH

    db = cantools.database.load_file(str(DBC_PATH))
    assert isinstance(db, cantools.database.can.Database)
    by_id = {m.frame_id: m for m in db.messages}

    def decode_one(spec: MessageSpec, data: bytes) -> object:
        return by_id[spec.base_id].decode(data, decode_choices=False)

    return decode_one


SCENES = (
    Scene("objects 100, spread", OutputMode.OBJECTS, 100),
    Scene("clusters 250, spread (5/target)", OutputMode.CLUSTERS, 250, per_target=5),
    Scene("objects 100, all in window", OutputMode.OBJECTS, 100, spread=False),
    Scene("clusters 250, all in window", OutputMode.CLUSTERS, 250, spread=False),
)
CLUSTER_COUNTS = (50, 250, 500)   # issue 6
BASELINE = "baseline scalar decode"
# Figure names for the suite's table (the scene names above are the benchmark's own).
_MODE_NAMES = {
    SCENES[0].name: "objects 100 +quality +extended, spread",
    SCENES[1].name: "clusters 250 +quality, spread",
    SCENES[2].name: "objects 100 +q +ext, all within 25 m",
    SCENES[3].name: "clusters 250 +quality, all within 25 m",
}


def scale_scene(n: int) -> Scene:
    return Scene(f"clusters {n}, spread (5/target)", OutputMode.CLUSTERS, n, per_target=5)


def measure(quick: bool) -> list[Result]:
    """Every scene (and the cluster counts of the scale figure): the pipeline beside its
    baselines, all in this run."""
    n_cycles = 40 if quick else 200
    scenes = list(SCENES) + [scale_scene(n) for n in CLUSTER_COUNTS if n != 250]
    cantools_decode = cantools_decoder()
    results: list[Result] = []
    for scene in scenes:
        cycles = scene_cycles(scene, n_cycles + 5)
        run_paired(cycles[:5])   # warm-up: imports, numpy code paths
        current, baseline = run_paired(cycles[5:])
        cycles = cycles[5:]
        for r in (current, baseline):
            r.scene = scene.name
        results += [current, baseline]
        results.append(Result(scene.name, "baseline decode only",
                              run_decode_only(cycles, scene.mode)))
        if cantools_decode is not None:
            results.append(Result(scene.name, "baseline cantools",
                                  run_per_frame(cycles, cantools_decode)))
    return results


def replay_processing_ms(pace: Pace, cycles: int) -> list[float]:
    """processing_ns of the first `cycles` cycles of the recording through the shell."""
    settings = RadarSettings(can=CanSettings(interface="replay"),
                             replay=ReplaySettings(file=str(RECORDING), pace=pace))
    stop = threading.Event()
    out: list[float] = []

    class Collect:
        def tracks(self, sensor: str, msg: RadarTracks) -> None:
            out.append(msg.processing_ns / 1e6)
            if len(out) >= cycles:
                stop.set()

        def status(self, sensor: str, msg: RadarStatus) -> None:
            pass

        def serving(self) -> None:
            pass

    RadarShell(settings, Collect()).run(stop)
    return out[3:]    # the first cycles pay for imports and first numpy calls


@dataclass
class Replay:
    """processing_ns (ms) on the recording, paced in real time and back to back."""

    realtime_ms: list[float]
    fast_ms: list[float]


def measure_replay(quick: bool) -> Replay:
    cycles = 40 if quick else 200
    return Replay(replay_processing_ms(Pace.REALTIME, cycles),
                  replay_processing_ms(Pace.FAST, cycles))


def replay_table(replay: Replay) -> str:
    lines = ["Service shell on the recording: RadarTracks.processing_ns (wall clock, ms)",
             f"{'recording (3-11 objects/cycle)':<34} {'pace':<24} {'median ms':>9} "
             f"{'p95 ms':>8} {'max ms':>8}"]
    for values, label in ((replay.realtime_ms, "real time (idle between)"),
                          (replay.fast_ms, "baseline: back to back")):
        lines.append(f"{'after last frame (processing_ns)':<34} {label:<24} "
                     f"{statistics.median(values):>9.3f} {np.percentile(values, 95):>8.3f} "
                     f"{max(values):>8.3f}")
    return "\n".join(lines)


def table(results: list[Result]) -> str:
    lines = ["CPU time per cycle (ms, this thread)",
             f"{'scene':<34} {'method':<26} {'median ms':>9} {'p95 ms':>8} "
             f"{'after last frame ms':>20}"]
    for r in results:
        after = f"{statistics.median(r.after_last_ms):.3f}" if r.after_last_ms else "-"
        lines.append(f"{r.scene:<34} {r.method:<26} {r.median_ms:>9.3f} {r.p95_ms:>8.3f} "
                     f"{after:>20}")
    return "\n".join(lines)


def _find(results: list[Result], scene: str, method: str) -> Result | None:
    return next((r for r in results if r.scene == scene and r.method == method), None)


def figures(results: list[Result], replay: Replay | None = None) -> list[Figure]:
    """The suite's figures: group "radar" (each mode's median and p95 per cycle against
    the 2 ms target, beside the scalar decode of the same frames measured in the same
    run; the recording's last-frame-to-tracks time) and group "scale" (clusters per
    cycle)."""
    load = [round(x, 2) for x in machine_info()["load_avg_1_5_15"]]
    figs: list[Figure] = []
    for scene, name in _MODE_NAMES.items():
        cur = _find(results, scene, "pipeline")
        ref = _find(results, scene, BASELINE)
        dec = _find(results, scene, "baseline decode only")
        if cur is None or ref is None:
            continue
        after = statistics.median(cur.after_last_ms or [0.0])
        extra = {"cycles": len(cur.per_cycle_ms), "load_avg_1_5_15": load,
                 "after_last_frame_median_ms": round(after, 3),
                 "decode_only_median_ms": None if dec is None else round(dec.median_ms, 3)}
        for stat, value, base in (("median", cur.median_ms, ref.median_ms),
                                  ("p95", cur.p95_ms, ref.p95_ms)):
            figs.append(Figure(
                "radar", f"{name}: {stat} per cycle", round(value, 3), "ms",
                baseline="the same frames decoded one by one (scalar decoder)",
                baseline_value=round(base, 3), target=f"< {TARGET_MS:g} ms",
                target_met=value < TARGET_MS,
                note="" if figs else ("CPU time per cycle of assembly, decode, prefilter, "
                                      "merge, tracking and messages (thread time)"),
                extra=extra))
    if replay is not None:
        figs.append(Figure(
            "radar", "recording: last frame -> tracks p95", round(float(
                np.percentile(replay.realtime_ms, 95)), 3), "ms",
            baseline="same, frames back to back",
            baseline_value=round(float(np.percentile(replay.fast_ms, 95)), 3),
            note="RadarTracks.processing_ns through the service shell, paced in real time",
            extra={"median_ms": round(statistics.median(replay.realtime_ms), 3)}))
    for n in CLUSTER_COUNTS:
        scene = scale_scene(n).name
        cur = _find(results, scene, "pipeline")
        ref = _find(results, scene, BASELINE)
        if cur is None or ref is None:
            continue
        figs.append(Figure(
            "scale", f"radar: {n} clusters per cycle, median", round(cur.median_ms, 3), "ms",
            baseline="the same frames decoded one by one (scalar decoder)",
            baseline_value=round(ref.median_ms, 3),
            note="" if n != CLUSTER_COUNTS[0] else (
                "clusters spread over the field, 5 returns per target, quality frames"),
            extra={"p95_ms": round(cur.p95_ms, 3), "baseline_p95_ms": round(ref.p95_ms, 3),
                   "cycles": len(cur.per_cycle_ms), "load_avg_1_5_15": load}))
    return figs


def _pyplot():  # type: ignore[no-untyped-def]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, out_dir: Path, name: str) -> Path:  # type: ignore[no-untyped-def]
    fig.tight_layout()
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / name
    fig.savefig(path, dpi=100)
    _pyplot().close(fig)
    return path


def plot(results: list[Result], out_dir: Path) -> Path:
    plt = _pyplot()
    scenes = [s.name for s in SCENES]
    methods = list(dict.fromkeys(r.method for r in results))
    fig, ax = plt.subplots(figsize=(11, 4.8))
    width = 0.8 / len(methods)
    for j, method in enumerate(methods):
        found = [_find(results, s, method) for s in scenes]
        ax.bar([i + j * width for i in range(len(scenes))],
               [0.0 if r is None else r.median_ms for r in found], width, label=method,
               yerr=[[0.0] * len(found), [0.0 if r is None else r.p95_ms - r.median_ms
                                          for r in found]], capsize=2)
    ax.axhline(TARGET_MS, color="red", linestyle="--", label=f"target {TARGET_MS:g} ms")
    ax.set_xticks([i + width * (len(methods) - 1) / 2 for i in range(len(scenes))])
    ax.set_xticklabels(scenes, fontsize=8)
    ax.set_ylabel("CPU time per cycle (ms, thread time)\nbar: median, whisker: p95")
    ax.set_title("ARS408 decode + tracking per radar cycle")
    ax.legend(fontsize=8)
    return _save(fig, out_dir, "radar_cycle_time.png")


def plot_scale(results: list[Result], out_dir: Path) -> Path:
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for method, style in (("pipeline", "o-"), (BASELINE, "s--"),
                          ("baseline decode only", "^:")):
        found = [(n, _find(results, scale_scene(n).name, method)) for n in CLUSTER_COUNTS]
        points = [(n, r) for n, r in found if r is not None]
        if not points:
            continue
        ax.errorbar([n for n, _ in points], [r.median_ms for _, r in points],
                    yerr=[[0.0] * len(points), [r.p95_ms - r.median_ms for _, r in points]],
                    fmt=style, capsize=3, label=method)
    ax.axhline(TARGET_MS, color="red", linestyle="--", label=f"target {TARGET_MS:g} ms (250)")
    ax.set_xlabel("clusters per cycle (spread, 5 returns per target, quality frames)")
    ax.set_ylabel("CPU time per cycle (ms)\npoint: median, whisker: p95")
    ax.set_title("Radar decode + tracking vs clusters per cycle")
    ax.set_xticks(list(CLUSTER_COUNTS))
    ax.legend(fontsize=8)
    return _save(fig, out_dir, "radar_cluster_scale.png")


def run(quick: bool, out_dir: Path) -> list[Figure]:
    """The suite's entry: measure, write both PNGs under `out_dir`, return the figures."""
    results = measure(quick)
    replay = measure_replay(quick)
    plot(results, out_dir)
    plot_scale(results, out_dir)
    return figures(results, replay)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_radar",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="40 cycles per scene, not 200")
    parser.add_argument("--out", default="out/bench", help="directory for the PNGs")
    args = parser.parse_args(argv)
    out = Path(args.out)
    machine = machine_info()
    print(f"{machine['cpu']} x{machine['cores']}, load {machine['load_avg_1_5_15']}")
    results = measure(args.quick)
    print(table(results))
    print()
    replay = measure_replay(args.quick)
    print(replay_table(replay))
    print()
    for f in figures(results, replay):
        met = "" if f.target_met is None else (" meets" if f.target_met else " MISSES")
        ratio = f" ({f.ratio:.2f}x)" if f.ratio is not None else ""
        print(f"[{f.group}] {f.name}: {f.value:.3f} {f.unit}, {f.baseline} "
              f"{f.baseline_value}{ratio}{met} {f.target}".rstrip())
    if not any(r.method == "baseline cantools" for r in results):
        print("(cantools not installed: no cantools row; `pip install cantools` to add it)")
    print(f"plots: {plot(results, out)}, {plot_scale(results, out)}")
    print(f"load average after the run: {[round(x, 2) for x in machine_info()['load_avg_1_5_15']]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
