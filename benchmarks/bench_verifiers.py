"""Verifier benchmark: each registered verifier's time per ROI beside the paper's gate.

    python -m benchmarks.bench_verifiers [--quick] [--out out/bench]

On rendered road scenes (SIMULATION: tools/sim/scenes.py, JPEG q80, decoded once as
fusion decodes), every obstacle's ROI and column as fusion builds them with the default
geometry (the paper's 2.2 m column, 22 px padding) at 6-25 m, plus one on empty road
per frame. Each verifier runs on the same observations, in short blocks taken in turn so
that a busy neighbour on a shared machine slows every verifier alike; one thread (as in
fusion). The baseline is `edge_density` (the paper's gate) measured in the same run.

What the verifiers are given: the grey frame; for `depth` and `combined` a depth image
of the frame's size with a return at the track's range on every pixel (the depth
verifier's full work: every band pixel tested); `hog_linear` and `combined` a weights
file of random coefficients written for the run (the cost does not depend on their
values; trained weights come from `aeb train-verifier`).

Writes bench_verifiers.json and bench_verifiers.png under --out; `run(quick, out_dir)`
returns the figures for the suite (`python -m benchmarks`).
"""

import json
import tempfile
from functools import partial
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.imaging import decode_gray
from aeb_radar_camera.services.fusion.roi import ColumnGeometry, ColumnProjector
from aeb_radar_camera.services.fusion.verifiers import Observation, Verifier, create, hog
from aeb_radar_camera.services.fusion.verifiers.appearance import HogLinearModel
from benchmarks.bench_gate import CALIBRATION, scenes, stats, timed
from benchmarks.figures import Figure, section_main

BASELINE = "edge_density"
_BLOCK = 10


def random_weights(path: Path) -> Path:
    """A hog_linear weights file of random coefficients (timing only)."""
    window = (32, 64)
    n = ((window[0] - hog.BLOCK) // hog.STRIDE + 1) * ((window[1] - hog.BLOCK)
                                                       // hog.STRIDE + 1) * 4 * hog.BINS
    coef = np.random.default_rng(0).normal(0, 0.01, n).astype(np.float32)
    HogLinearModel(window, 1.25, coef, 0.0, 0.5,
                   {"note": "random coefficients for bench_verifiers (timing only)"}
                   ).save(path)
    return path


def verifiers(weights: Path) -> dict[str, tuple[Verifier, bool]]:
    """name -> (verifier, given depth)."""
    w = str(weights)
    return {BASELINE: (create(BASELINE), False),
            "adaptive_edge_density": (create("adaptive_edge_density"), False),
            "depth": (create("depth"), True),
            "hog_people": (create("hog_people"), False),
            "hog_linear": (create("hog_linear", {"weights": w}), False),
            "combined (depth + hog_linear)": (create("combined", {"weights": w}), True),
            "combined, no depth (hog_linear only)": (create("combined", {"weights": w}),
                                                     False)}


def observations(cal: Calibration, n_frames: int) -> list[tuple[Observation, Observation]]:
    """(with depth, without depth) per ROI, fusion's default geometry."""
    projector = ColumnProjector(cal, ColumnGeometry())
    rng = np.random.default_rng(3)
    out = []
    for jpeg, obstacles in scenes(cal, n_frames, seed=200):
        gray = decode_gray(jpeg.tobytes())
        xy = [(o.x_m, o.y_m) for o in obstacles] + [(float(rng.uniform(6, 25)), 0.0)]
        for (x, y), got in zip(xy, projector.boxes(np.array(xy)), strict=True):
            if got is None:
                continue
            roi, column = got
            r = float(np.hypot(x, y))
            depth = np.full(gray.shape, r, np.float32)
            out.append((Observation(gray, roi, column, r, depth, cal, (x, y)),
                        Observation(gray, roi, column, r)))
    return out


def time_verifiers(vs: dict[str, tuple[Verifier, bool]],
                   obs: list[tuple[Observation, Observation]],
                   reps: int) -> dict[str, dict[str, float]]:
    samples: dict[str, list[float]] = {name: [] for name in vs}
    cv2.setNumThreads(1)
    for with_depth, without in obs:
        runs = [(name, partial(v.verify, with_depth if depth else without))
                for name, (v, depth) in vs.items()]
        for _ in range(max(1, reps // _BLOCK)):
            for name, fn in runs:
                fn()
                samples[name].extend(timed(fn, min(reps, _BLOCK)))
    return {name: stats(s) for name, s in samples.items()}


def print_report(summary: dict[str, dict[str, float]], n_rois: int,
                 sizes: list[int]) -> None:
    base = summary[BASELINE]["mean_us"]
    print(f"Verifier time per ROI ({n_rois} ROIs as fusion builds them, "
          f"{min(sizes)}-{max(sizes)} px; one thread; SIMULATED frames)\n")
    print(f"| verifier | mean us | p50 us | p95 us | x {BASELINE} |")
    print("|---|---|---|---|---|")
    for name, s in summary.items():
        print(f"| {name} | {s['mean_us']:.0f} | {s['p50_us']:.0f} | {s['p95_us']:.0f} | "
              f"{s['mean_us'] / base:.1f} |")


def plot(summary: dict[str, dict[str, float]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(summary)
    fig, ax = plt.subplots(figsize=(8, 4))
    y = np.arange(len(names))
    ax.barh(y, [summary[n]["mean_us"] for n in names], color="tab:blue", label="mean")
    ax.scatter([summary[n]["p95_us"] for n in names], y, color="black", marker="|", s=200,
               label="p95")
    ax.set_yticks(y, names)
    ax.invert_yaxis()
    ax.set_xlabel("time per ROI (us), one thread")
    ax.set_title("Verifiers per ROI beside the paper's gate (edge_density)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def figures(summary: dict[str, dict[str, float]]) -> list[Figure]:
    base = summary[BASELINE]["mean_us"]
    return [Figure("verifiers", f"{name} per ROI, mean", s["mean_us"], "us",
                   baseline=f"{BASELINE} (the paper's gate)", baseline_value=base,
                   extra={"p95_us": s["p95_us"]})
            for name, s in summary.items() if name != BASELINE]


def run(quick: bool, out_dir: Path) -> list[Figure]:
    cal = Calibration.load(CALIBRATION)
    n_frames, reps = (2, 20) if quick else (8, 100)
    obs = observations(cal, n_frames)
    with tempfile.TemporaryDirectory() as tmp:
        vs = verifiers(random_weights(Path(tmp) / "weights.json"))
        summary = time_verifiers(vs, obs, reps)
    sizes = [o.roi.area for o, _ in obs]
    print_report(summary, len(obs), sizes)
    out_dir.mkdir(parents=True, exist_ok=True)
    result: dict[str, Any] = {"rois": len(obs), "reps_per_roi": reps,
                              "roi_px": [min(sizes), max(sizes)], "timing": summary}
    (out_dir / "bench_verifiers.json").write_text(json.dumps(result, indent=2))
    plot(summary, out_dir / "bench_verifiers.png")
    print(f"\nwrote {out_dir / 'bench_verifiers.json'} and {out_dir / 'bench_verifiers.png'}")
    return figures(summary)


def main(argv: list[str] | None = None) -> int:
    return section_main("bench_verifiers", __doc__, run, argv, "few frames and repetitions")


if __name__ == "__main__":
    raise SystemExit(main())
