"""The benchmark suite: every section measured beside its baseline in the same run, one
table, one JSON file and one PNG chart. `python -m benchmarks` or `aeb bench`.

Sections (each a module with `run(quick, out_dir) -> list[Figure]`):
- gate: the edge-density gate per ROI vs the paper's naive code, and the full frame;
- depth: depth frames on the wire (bytes, encode, decode per codec and size) beside the
  colour JPEG, and the depth verifier per ROI beside the paper's gate;
- radar: decode + tracking per cycle (object and cluster mode), clusters 50/250/500;
- fusion: tracks received -> BrakeCommand with 1..128 tracks and 1/2/4 cameras;
- brake: command receipt -> serial write;
- latency: last CAN frame -> brake bytes on the actuator, per stage, beside both floors
  (same-transport relays, bare Zenoh hops);
- cost: CPU share and memory of each service while demo scenarios run;
- eval: `aeb eval` on a recording, ROIs/s per core, the paper's 131,603 frames projected;
- record: `aeb record` at nominal rates, messages published vs recorded per key (30 s
  here; `python -m benchmarks.bench_record --minutes 10` for the 10-minute run);
- rerun: `aeb rerun fusion` in multiples of real time per core;
- sim: the simulator's rendered frame (day, dusk, night, rain, bend) and world step.
"""

import argparse
import importlib
import sys
import time
import traceback
from pathlib import Path

from aeb_radar_camera.common.log import add_log_level, setup_logging
from aeb_radar_camera.tools.machine import machine_info
from benchmarks.figures import Figure
from benchmarks.report import plot, print_table, write_json

SECTIONS: dict[str, str] = {
    "gate": "benchmarks.bench_gate",
    "verifiers": "benchmarks.bench_verifiers",
    "depth": "benchmarks.bench_depth",
    "radar": "benchmarks.bench_radar",
    "fusion": "benchmarks.bench_fusion",
    "brake": "benchmarks.bench_brake",
    "latency": "benchmarks.bench_latency",
    "cost": "benchmarks.bench_cost",
    "eval": "benchmarks.bench_eval",
    "record": "benchmarks.bench_record",
    "rerun": "benchmarks.bench_rerun",
    "sim": "benchmarks.bench_sim",
}


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="aeb bench", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="short runs (under a minute in all)")
    p.add_argument("--only", default="", help=f"comma-separated sections of {list(SECTIONS)}")
    p.add_argument("--out", default="out/bench", help="JSON, PNG and per-section files")
    add_log_level(p, "WARNING")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging("bench", args.log_level)
    names = [n.strip() for n in args.only.split(",") if n.strip()] or list(SECTIONS)
    unknown = [n for n in names if n not in SECTIONS]
    if unknown:
        print(f"error: unknown section(s) {unknown}; choose from {list(SECTIONS)}",
              file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    machine = machine_info()
    print(f"benchmark suite ({'quick' if args.quick else 'full'}) on {machine['cpu']} "
          f"x{machine['cores']}, load {machine['load_avg_1_5_15']}", flush=True)
    figures: list[Figure] = []
    failed: list[str] = []
    timings: dict[str, float] = {}
    t_all = time.monotonic()
    for i, name in enumerate(names, 1):
        print(f"[{i}/{len(names)}] {name} ...", flush=True)
        t0 = time.monotonic()
        try:
            module = importlib.import_module(SECTIONS[name])
            got = module.run(args.quick, out)
        except (RuntimeError, OSError):   # a process or device that did not come up
            traceback.print_exc()
            failed.append(name)
            continue
        timings[name] = round(time.monotonic() - t0, 1)
        figures += got
        print(f"[{i}/{len(names)}] {name}: {len(got)} figures in {timings[name]:.0f} s",
              flush=True)
    total = time.monotonic() - t_all
    print()
    print_table(figures, sys.stdout)
    json_path = write_json(figures, machine, out / "suite.json", {
        "mode": "quick" if args.quick else "full", "seconds": round(total, 1),
        "section_seconds": timings, "failed_sections": failed})
    png = plot(figures, out / "suite.png",
               f"AEB benchmark suite ({'quick' if args.quick else 'full'}), "
               f"{machine['cores']} cores, load {machine['load_avg_1_5_15'][0]}")
    missed = [f"{f.group}/{f.name}" for f in figures if f.target_met is False]
    print(f"\n{len(figures)} figures in {total:.0f} s; {json_path}, {png}")
    if missed:
        print(f"targets missed: {', '.join(missed)}")
    if failed:
        print(f"error: section(s) failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
