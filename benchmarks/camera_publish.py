"""Camera benchmark: JPEG encode time at 848x480, and the camera's publish rate and
capture-to-subscriber latency through a Zenoh router, normal and with a slow encoder
(drop-not-queue: the latency must stay flat while frames are dropped).

    python -m benchmarks.camera_publish [--quick] [--out out/bench/]

Baseline in the same run: cv2.imencode at the same quality.
"""

import argparse
import subprocess
import sys
import threading
import time
from pathlib import Path

import cv2
import numpy as np

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.clock import wall_ns
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.config.camera import CameraSettings, SyntheticSource
from aeb_radar_camera.common.imaging import encode_jpeg
from aeb_radar_camera.common.keys import CAMERA_JPEG
from aeb_radar_camera.common.messages import CompressedFrame
from aeb_radar_camera.common.net import free_port
from aeb_radar_camera.common.resources import EXAMPLE_CALIBRATION
from aeb_radar_camera.services.camera.shell import CameraShell
from aeb_radar_camera.tools.sim.moving_box import MovingBoxSource
from benchmarks.processes import stop_processes

CALIBRATION = EXAMPLE_CALIBRATION


def percentiles(values_us: list[float]) -> tuple[float, float]:
    arr = np.array(values_us)
    return float(np.percentile(arr, 50)), float(np.percentile(arr, 95))


def bench_encode(n: int, qualities: tuple[int, ...]) -> list[tuple[str, float, float, float]]:
    """(what, median us, p95 us, KB) per encoder and quality."""
    scene = MovingBoxSource(Calibration.load(CALIBRATION), 30.0)
    frames = [scene.render(i) for i in range(16)]
    rows = []
    cases = [(f"imaging.encode_jpeg q{q}", q, False) for q in qualities]
    cases.append(("baseline cv2.imencode q80", 80, True))
    for name, quality, baseline in cases:
        times, size = [], 0
        for i in range(n):
            img = frames[i % len(frames)]
            t0 = time.perf_counter_ns()
            if baseline:
                _, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, quality])
                size = len(buf)
            else:
                size = len(encode_jpeg(img, quality))
            times.append((time.perf_counter_ns() - t0) / 1e3)
        p50, p95 = percentiles(times)
        rows.append((name, p50, p95, size / 1024))
    return rows


def run_camera(endpoint: str, seconds: float, encode_delay_s: float
               ) -> tuple[float, list[float], int, int, int]:
    """Run a camera (the moving-box demo scene at 30 fps) and a subscriber for `seconds`.

    Returns (received rate Hz, per-frame latency capture->receipt ms, published, dropped,
    received)."""
    settings = CameraSettings(calibration=str(CALIBRATION), name="bench", fps=30.0,
                              source=SyntheticSource(), stats_period_s=0.0)
    cal = Calibration.load(CALIBRATION)
    client = ZenohSettings(mode=ZenohMode.CLIENT, connect=(endpoint,))
    latencies: list[float] = []
    receipts: list[float] = []
    lock = threading.Lock()

    def on_frame(msg: CompressedFrame, key: str) -> None:
        now = wall_ns()
        with lock:
            latencies.append((now - msg.header.stamp_ns) / 1e6)
            receipts.append(time.monotonic())

    with Bus.open(client, "ego", "bench-sub") as sub_bus, \
            Bus.open(client, "ego", "camera/bench") as cam_bus:
        sub_bus.subscribe(CAMERA_JPEG, on_frame, camera="bench")
        source = MovingBoxSource(cal, 30.0)
        shell = CameraShell(settings, cal, source, cam_bus)
        if encode_delay_s:
            def slow(image: np.ndarray, quality: int) -> bytes:
                time.sleep(encode_delay_s)   # simulates a slow encoder or a loaded CPU
                return encode_jpeg(image, quality)
            shell.pipeline._encode = slow
        stop = threading.Event()
        thread = threading.Thread(target=shell.run, args=(stop,))
        thread.start()
        time.sleep(seconds)
        stop.set()
        thread.join(10)
        stats = shell.core.stats
    with lock:
        rate = (len(receipts) - 1) / (receipts[-1] - receipts[0]) if len(receipts) > 1 else 0.0
        return rate, list(latencies), stats.published, stats.dropped, len(latencies)


def plot(out: Path, encode_rows: list[tuple[str, float, float, float]],
         runs: dict[str, list[float]]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.5))
    names = [r[0] for r in encode_rows]
    a.barh(names, [r[1] for r in encode_rows], xerr=[[0] * len(encode_rows),
                                                     [r[2] - r[1] for r in encode_rows]])
    a.set_xlabel("encode time, median (bar) to p95 (us), 848x480")
    for name, lat in runs.items():
        b.plot(lat, label=name, lw=0.8)
    b.set_xlabel("frame received")
    b.set_ylabel("capture -> subscriber latency (ms)")
    b.legend()
    b.set_title("drop, not queue: latency stays flat")
    fig.tight_layout()
    out.mkdir(parents=True, exist_ok=True)
    path = out / "camera_publish.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="camera_publish", description=__doc__)
    parser.add_argument("--quick", action="store_true", help="fewer samples, shorter runs")
    parser.add_argument("--out", default="out/bench/", help="directory for the PNG plot")
    args = parser.parse_args(argv)
    n, seconds = (100, 3.0) if args.quick else (500, 10.0)

    encode_rows = bench_encode(n, (60, 80, 95))
    print(f"JPEG encode, 848x480 rendered road scene (simulation), {n} frames")
    print(f"{'encoder':<28} {'median us':>10} {'p95 us':>10} {'KB':>7}")
    for name, p50, p95, kb in encode_rows:
        print(f"{name:<28} {p50:>10.0f} {p95:>10.0f} {kb:>7.1f}")

    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router = subprocess.Popen([sys.executable, "-m", "aeb_radar_camera.common.router", "--listen",
                               endpoint],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    runs: dict[str, list[float]] = {}
    try:
        print(f"\nCamera at 30 fps through a router, {seconds:g} s per run")
        print(f"{'run':<28} {'rate Hz':>8} {'lat p50 ms':>11} {'lat p95 ms':>11} "
              f"{'published':>10} {'dropped':>8}")
        for name, delay in (("normal encoder", 0.0), ("encoder slowed to 50 ms", 0.05)):
            rate, lat, published, dropped, _received = run_camera(endpoint, seconds, delay)
            runs[name] = lat
            p50, p95 = percentiles(lat) if lat else (float("nan"), float("nan"))
            print(f"{name:<28} {rate:>8.2f} {p50:>11.2f} {p95:>11.2f} {published:>10} "
                  f"{dropped:>8}")
    finally:
        stop_processes([router])
    print(f"\nplot: {plot(Path(args.out), encode_rows, runs)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

