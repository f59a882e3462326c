"""Depth benchmark: what depth costs on the wire and in the verifier.

    python -m benchmarks.bench_depth [--quick] [--out out/bench]

1. Encoding, per depth frame, for the candidate lossless codecs (common/depth_image.py:
   zstd level 1, PNG level 1) at the D435's 848x480 and decimated to 424x240: bytes,
   encode time (the camera's publish thread) and decode time as fusion decodes (message,
   codec, metres, nearest-neighbour up to 848x480: services/fusion/frames.py), beside the
   colour frame's JPEG (q80, the camera's one JPEG path) measured in the same run. Depth
   images are ray-cast road scenes with cars and a wall (tools/eval/depth.py, a
   SIMULATION), clean and with the D435's noise model (common/depth_error.py: independent
   per-pixel noise, the worst case for a compressor; a real D435's error is partly
   correlated between neighbours).
2. The depth verifier's time per ROI beside the paper's gate (edge_density) on the same
   ROIs of the same frames, timed in alternating short blocks.

Writes bench_depth.json and bench_depth.png under --out; `run(quick, out_dir)` returns
the suite's figures (`python -m benchmarks --only depth`).
"""

import json
import math
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.depth_error import D435Noise
from aeb_radar_camera.common.depth_image import CODECS, encode_depth, to_units
from aeb_radar_camera.common.imaging import decode_gray, encode_jpeg
from aeb_radar_camera.common.messages import DepthFrame, Header, encode
from aeb_radar_camera.common.resources import EXAMPLE_CALIBRATION
from aeb_radar_camera.services.fusion.frames import decode_depth_frame
from aeb_radar_camera.services.fusion.roi import ColumnGeometry, ColumnProjector
from aeb_radar_camera.services.fusion.verifiers import Observation, create
from aeb_radar_camera.tools.eval.depth import box_scene_depth, car_box
from aeb_radar_camera.tools.messages import ObjectKind
from aeb_radar_camera.tools.sim.scenes import Obstacle, Scene, render
from benchmarks.bench_gate import stats, timed
from benchmarks.figures import Figure, section_main

RESOLUTIONS = {"848x480": 1, "424x240": 2}
_BLOCK = 10


def scenes(cal: Calibration, n: int, seed: int
           ) -> list[tuple[np.ndarray, np.ndarray, list[tuple[float, float]]]]:
    """(colour BGR, clean depth, obstacle positions) of `n` random road scenes."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        cars = [(float(rng.uniform(6, 25)), float(rng.uniform(-3, 3))) for _ in range(3)]
        wall = (5.0, 40.0, 6.0, 6.3, 0.0, 2.5)        # a wall along the road's left edge
        depth = box_scene_depth(cal, (*(car_box(x, y) for x, y in cars), wall))
        colour = render(cal, Scene(obstacles=tuple(Obstacle(x, y, ObjectKind.CAR)
                                                   for x, y in cars), seed=seed + i))
        out.append((colour, depth, cars))
    return out


def decimate_and_encode(units: np.ndarray, k: int, codec: str) -> bytes:
    """What the camera's publish thread does with a frame's depth."""
    return encode_depth(units[::k, ::k], codec)


def depth_message(units: np.ndarray, codec: str) -> bytes:
    return encode(DepthFrame(header=Header(0, "camera/front", 0, 0), camera="front",
                             width=units.shape[1], height=units.shape[0], codec=codec,
                             data=encode_depth(units, codec)))


def time_encodings(cal: Calibration, frames: list[Any], reps: int,
                   rng: np.random.Generator) -> dict[str, dict[str, Any]]:
    """Bytes, encode and fusion-side decode time per codec, resolution and noise."""
    noise = D435Noise()
    out: dict[str, dict[str, Any]] = {}
    jpeg_bytes, jpeg_us = [], []
    for colour, depth, _ in frames:
        jpeg_bytes.append(len(encode_jpeg(colour, 80)))
        jpeg_us += timed(partial(encode_jpeg, colour, 80), reps)
        for noisy in (False, True):
            d = noise.apply(depth, rng) if noisy else depth
            units_full = to_units(d)
            for res, k in RESOLUTIONS.items():
                units = np.ascontiguousarray(units_full[::k, ::k])
                for codec in CODECS:
                    label = f"{codec} {res} {'D435 noise' if noisy else 'clean'}"
                    r = out.setdefault(label, {"bytes": [], "encode": [], "decode": [],
                                               "codec": codec, "resolution": res,
                                               "noisy": noisy})
                    payload = depth_message(units, codec)
                    r["bytes"].append(len(payload))
                    # The camera decimates then encodes; fusion decodes to 848x480 metres.
                    r["encode"] += timed(partial(decimate_and_encode, units_full, k, codec),
                                         reps)
                    r["decode"] += timed(partial(decode_depth_frame, payload, cal.width,
                                                 cal.height), reps)
    summary: dict[str, dict[str, Any]] = {}
    raw = cal.width * cal.height * 2
    for label, r in out.items():
        k = RESOLUTIONS[r["resolution"]]
        summary[label] = {"codec": r["codec"], "resolution": r["resolution"],
                          "noisy": r["noisy"], "bytes_mean": float(np.mean(r["bytes"])),
                          "raw_bytes": raw // (k * k),
                          "encode": stats(r["encode"]), "decode": stats(r["decode"])}
    summary["jpeg q80 848x480 (colour)"] = {"bytes_mean": float(np.mean(jpeg_bytes)),
                                            "encode": stats(jpeg_us)}
    return summary


def time_verifiers(cal: Calibration, frames: list[Any], reps: int,
                   rng: np.random.Generator) -> dict[str, Any]:
    """Per-ROI time of depth and edge_density on the same ROIs; and their verdicts on the
    cars and on empty road at the same ranges (a sanity check, not an evaluation)."""
    projector = ColumnProjector(cal, ColumnGeometry())
    depth_v, gate = create("depth"), create("edge_density")
    noise = D435Noise()
    times: dict[str, list[float]] = {"depth": [], "edge_density": []}
    verdicts = {"car": [0, 0], "road": [0, 0], "car hidden by a nearer one": [0, 0]}
    for colour, depth, cars in frames:
        gray = decode_gray(encode_jpeg(colour, 80))
        d = noise.apply(depth, rng)
        tracks = [(x, y, "car") for x, y in cars] + [(x, -y - 8.0, "road") for x, y in cars]
        for x, y, kind in tracks:
            got = projector.boxes(np.array([[x, y]]))[0]
            if got is None:
                continue
            obs = Observation(gray, got[0], got[1], math.hypot(x, y), d, cal, (x, y))
            result = depth_v.verify(obs)
            if kind == "car" and result.detail["nearer"] > 0.5:
                kind = "car hidden by a nearer one"
            verdicts[kind][0] += int(result.verified)
            verdicts[kind][1] += 1
            for _ in range(max(1, reps // _BLOCK)):
                times["depth"] += timed(partial(depth_v.verify, obs), min(reps, _BLOCK))
                times["edge_density"] += timed(partial(gate.verify, obs), min(reps, _BLOCK))
    return {"timing": {k: stats(v) for k, v in times.items()},
            "verified": {k: {"passed": v[0], "of": v[1]} for k, v in verdicts.items()}}


def print_report(enc: dict[str, dict[str, Any]], ver: dict[str, Any]) -> None:
    print("\nDepth frame encodings (mean over frames; decode = fusion's whole path)")
    print(f"{'encoding':<30} {'bytes':>9} {'of raw':>7} {'enc us':>8} {'dec us':>8} "
          f"{'MB/s @30Hz':>10}")
    for label, r in enc.items():
        share = f"{r['bytes_mean'] / r['raw_bytes']:.1%}" if "raw_bytes" in r else "-"
        dec = f"{r['decode']['mean_us']:8.0f}" if "decode" in r else "       -"
        print(f"{label:<30} {r['bytes_mean']:9.0f} {share:>7} {r['encode']['mean_us']:8.0f} "
              f"{dec} {r['bytes_mean'] * 30 / 1e6:10.2f}")
    print("\nVerifier time per ROI (us), same ROIs")
    for name, s in ver["timing"].items():
        print(f"  {name:<14} mean {s['mean_us']:7.1f}  p50 {s['p50_us']:7.1f}  "
              f"p95 {s['p95_us']:7.1f}  (n {s['n']})")
    v = ver["verified"]
    print(f"  depth verified {v['car']['passed']}/{v['car']['of']} cars in view, "
          f"{v['car hidden by a nearer one']['passed']}/{v['car hidden by a nearer one']['of']}"
          f" hidden by a nearer car, {v['road']['passed']}/{v['road']['of']} empty-road "
          "columns (SIMULATION)")


def plot(enc: dict[str, dict[str, Any]], ver: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(16, 4.8))
    labels = list(enc)
    xs = np.arange(len(labels))
    axes[0].bar(xs, [enc[k]["bytes_mean"] / 1e3 for k in labels], color="tab:blue")
    axes[0].set_ylabel("kB per frame")
    axes[0].set_title("bytes per depth frame (JPEG colour frame for scale)")
    width = 0.4
    axes[1].bar(xs - width / 2, [enc[k]["encode"]["mean_us"] / 1e3 for k in labels], width,
                label="encode (camera)")
    axes[1].bar(xs + width / 2, [enc[k].get("decode", {"mean_us": 0})["mean_us"] / 1e3
                                 for k in labels], width, label="decode to metres (fusion)")
    axes[1].set_ylabel("ms per frame")
    axes[1].legend(fontsize=8)
    axes[1].set_title("time per depth frame")
    for ax in axes[:2]:
        ax.set_xticks(xs, [k.replace(" ", "\n", 2) for k in labels], fontsize=6)
    names = list(ver["timing"])
    axes[2].bar(names, [ver["timing"][n]["mean_us"] for n in names], color="tab:green")
    axes[2].scatter(names, [ver["timing"][n]["p95_us"] for n in names], marker="_", s=200,
                    color="black", zorder=3)
    axes[2].set_ylabel("us per ROI (bar: mean, dash: p95)")
    axes[2].set_title("verifier per ROI, same ROIs")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def figures(enc: dict[str, dict[str, Any]], ver: dict[str, Any]) -> list[Figure]:
    jpeg = enc["jpeg q80 848x480 (colour)"]
    out = []
    for label, r in enc.items():
        if "raw_bytes" not in r or not r["noisy"]:
            continue
        out.append(Figure("depth", f"{label}: bytes per frame", r["bytes_mean"], "B",
                          baseline="colour JPEG q80, same scenes",
                          baseline_value=jpeg["bytes_mean"],
                          extra={"raw_bytes": r["raw_bytes"]}))
        out.append(Figure("depth", f"{label}: encode", r["encode"]["mean_us"], "us",
                          baseline="colour JPEG encode, same run",
                          baseline_value=jpeg["encode"]["mean_us"],
                          extra={"decode_us": r["decode"]["mean_us"]}))
    t = ver["timing"]
    out.append(Figure("depth", "depth verifier per ROI, mean", t["depth"]["mean_us"], "us",
                      baseline="edge_density, same ROIs",
                      baseline_value=t["edge_density"]["mean_us"],
                      extra={"p95_us": t["depth"]["p95_us"],
                             "baseline_p95_us": t["edge_density"]["p95_us"]}))
    return out


def run(quick: bool, out_dir: Path) -> list[Figure]:
    """Measure, print, write JSON and PNG under `out_dir`; the suite's figures."""
    cal = Calibration.load(str(EXAMPLE_CALIBRATION))
    n_frames, reps = (2, 2) if quick else (6, 30)
    rng = np.random.default_rng(5)
    frames = scenes(cal, n_frames, seed=200)
    enc = time_encodings(cal, frames, reps, rng)
    ver = time_verifiers(cal, frames, 5 * reps, rng)
    print_report(enc, ver)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "bench_depth.json").write_text(json.dumps(
        {"frames": n_frames, "reps": reps, "encodings": enc, "verifiers": ver}, indent=2))
    plot(enc, ver, out_dir / "bench_depth.png")
    print(f"\nwrote {out_dir / 'bench_depth.json'} and {out_dir / 'bench_depth.png'}")
    return figures(enc, ver)


def main(argv: list[str] | None = None) -> int:
    return section_main("bench_depth", __doc__, run, argv, "few frames and repetitions")


if __name__ == "__main__":
    raise SystemExit(main())
