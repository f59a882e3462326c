"""Process replay speed: `aeb rerun fusion` over a demo recording, in multiples of real
time per core (recorded seconds / CPU seconds of the re-run; one thread).

The recording: the demo recording kept in tests/data/recording/ (camera at 10 fps: the
suite's run), one given with `--recording` (e.g. of `aeb demo`), or with `--record-demo`
one made here (demo scenarios in closed loop, tools/sim/session.py, camera at 30 fps,
`aeb record` beside the stack). Fusion's core is re-run over it with the shipped config,
frames decoded only when a cycle's gate reads them.

Baselines, in the same run: reading the recording alone (the floor: every record read
and its message decoded, no fusion), and the re-run plus decoding every recorded frame
(what a re-run costs that decodes every frame, as live fusion does).

    python -m benchmarks.bench_rerun [--recording FILE.mcap | --record-demo]
"""

import argparse
import json
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import load_config
from aeb_radar_camera.common.imaging import decode_gray
from aeb_radar_camera.common.messages import CompressedFrame, decode
from aeb_radar_camera.tools.machine import machine_info
from aeb_radar_camera.tools.recording.reader import Recording, decode_record
from aeb_radar_camera.tools.recording.rerun_fusion import FusionRerun
from benchmarks.figures import Figure
from benchmarks.processes import stop_processes

TARGET_RTF = 20.0
FULL_SCENARIOS = ("stationary_car_30kph", "pedestrian_crossing_20kph")
REPO = Path(__file__).resolve().parents[1]
KEPT = REPO / "tests" / "data" / "recording" / "pedestrian_standing_20kph.mcap"


def record_demo(scenarios: tuple[str, ...], out_dir: Path) -> Path:
    """Run the scenarios in closed loop with `aeb record` beside the stack. Raises
    RuntimeError when the recorder does not come up."""
    from aeb_radar_camera.tools.sim.scenario import find_scenario, load_scenario
    from aeb_radar_camera.tools.sim.session import SETTLE_TIMEOUT_S, closed_loop

    path = out_dir / "rerun-bench.mcap"
    path.unlink(missing_ok=True)
    with closed_loop(out_dir / "rerun-run", log=sys.stdout) as loop:
        up = threading.Event()
        loop.bus.subscribe_health(lambda s, i, alive: up.set() if s == "record" and alive
                                  else None)
        rec = subprocess.Popen([sys.executable, "-m", "aeb_radar_camera.tools.cli", "record", "-o",
                                str(path),
                                "--connect", loop.endpoint], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
        try:
            if not up.wait(120):
                raise RuntimeError("the recorder did not come up")
            for name in scenarios:
                print(f"  running {name} ...", flush=True)
                loop.sim.run(load_scenario(find_scenario(name)))
                loop.sim.wait_settled(SETTLE_TIMEOUT_S)
        finally:
            stop_processes([rec], timeout_s=60)
    return path


def measure(path: Path) -> dict[str, Any]:
    cfg = load_config(REPO / "deploy" / "fusion.toml", FusionConfig)
    rec = Recording.open(path)
    first, last = rec.time_range()
    # Floor: read every record the re-run reads, and decode its message.
    rerun = FusionRerun(cfg)
    t0 = time.process_time()
    n_read = 0
    for r in rec.records(rerun.topics):
        decode_record(r)
        n_read += 1
    read_cpu = time.process_time() - t0
    # The re-run.
    rerun = FusionRerun(cfg)
    t0 = time.process_time()
    cycles = sum(1 for _ in rerun.run(rec))
    rerun_cpu = time.process_time() - t0
    # Every frame decoded: what the lazy decoding saves.
    t0 = time.process_time()
    frames = 0
    for r in rec.records([t for t in rerun.topics if t.endswith("/jpeg")]):
        decode_gray(decode(r.data, CompressedFrame).jpeg)
        frames += 1
    decode_all_cpu = time.process_time() - t0
    st = rerun.stats
    # What was re-run: from the first to the last record it read.
    span_s = ((st.last_log_ns or last) - (st.first_log_ns or first)) / 1e9
    return {"recording": str(path), "span_s": span_s, "cycles": cycles, "records": n_read,
            "read_cpu_s": read_cpu, "rerun_cpu_s": rerun_cpu,
            "decode_all_cpu_s": decode_all_cpu, "frames": frames,
            "frames_decoded": st.frames_decoded, "frames_pinned": st.frames_pinned}


def figures_from(m: dict[str, Any]) -> list[Figure]:
    span = m["span_s"]
    rtf = span / m["rerun_cpu_s"]
    every = span / (m["rerun_cpu_s"] + m["decode_all_cpu_s"])
    return [
        Figure("rerun", "fusion re-run", round(rtf, 1), "x real time per core",
               baseline="reading the recording alone", baseline_value=round(
                   span / m["read_cpu_s"], 1),
               target=f">= {TARGET_RTF:g}x", target_met=rtf >= TARGET_RTF,
               note=f"{m['cycles']} radar cycles, {span:.0f} s recorded, "
                    f"{m['rerun_cpu_s']:.2f} CPU s"),
        Figure("rerun", "fusion re-run decoding every frame", round(every, 1),
               "x real time per core", baseline="the re-run (frames when used)",
               baseline_value=round(rtf, 1),
               note=f"frames decoded {m['frames_decoded']} of {m['frames']}"),
    ]


def run(quick: bool, out_dir: Path, recording: str = "", demo: bool = False) -> list[Figure]:
    path = Path(recording) if recording else (
        record_demo(FULL_SCENARIOS, out_dir) if demo else KEPT)
    m = measure(path)
    (out_dir / "bench_rerun.json").write_text(json.dumps(m, indent=1))
    return figures_from(m)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_rerun",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--recording", default="", help="re-run this one")
    parser.add_argument("--record-demo", action="store_true",
                        help="record demo scenarios first and re-run that")
    parser.add_argument("--out", default="out/bench")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    figs = run(False, out, args.recording, args.record_demo)
    from benchmarks.report import print_table

    print_table(figs, sys.stdout)
    print(f"machine: {machine_info()['cpu']}; ({time.monotonic() - t0:.0f} s; "
          f"{out / 'bench_rerun.json'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
