"""Cost at nominal rates: CPU share and resident memory of each service while demo
scenarios run in closed loop (radar ~13.3 Hz, camera 30 fps, one fusion instance).

Baseline, in the same run: a null service (benchmarks/null_service.py), a Python process
with a Zenoh session receiving every key of the stack and doing nothing.

    python -m benchmarks.bench_cost [--quick] [--out out/bench]
"""

import argparse
import json
import subprocess
import sys
import threading
import time
from pathlib import Path

from aeb_radar_camera.tools.machine import machine_info
from aeb_radar_camera.tools.sim.scenario import find_scenario, load_scenario
from aeb_radar_camera.tools.sim.session import SETTLE_TIMEOUT_S, ClosedLoop, closed_loop
from benchmarks.figures import Figure
from benchmarks.proc_sampler import ProcSampler, Usage
from benchmarks.processes import stop_processes

# The bars: radar under 5% of a core, fusion under 15%, brake under 2%, each under 150 MB.
CPU_TARGET_PCT = {"radar": 5.0, "fusion": 15.0, "brake": 2.0}
RSS_TARGET_MB = 150.0
SERVICES = ("radar", "camera", "fusion", "brake")
QUICK_SCENARIOS = ("stationary_car_30kph",)
FULL_SCENARIOS = ("stationary_car_30kph", "pedestrian_crossing_20kph",
                  "no_threat_parked_cars_30kph")
MB = 1024 * 1024


def start_null_service(loop: ClosedLoop, timeout_s: float = 60.0) -> subprocess.Popen[bytes]:
    """The baseline process, once its liveliness token is seen. Raises RuntimeError."""
    up = threading.Event()
    loop.bus.subscribe_health(
        lambda service, instance, alive: up.set() if (service, instance, alive) == (
            "bench", "null", True) else None)
    proc = subprocess.Popen([sys.executable, "-m", "benchmarks.null_service",
                             "--connect", loop.endpoint],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    if not up.wait(timeout_s):
        proc.kill()
        raise RuntimeError("the null service did not come up")
    return proc


def measure(scenarios: tuple[str, ...], out_dir: Path, log: bool = True
            ) -> tuple[dict[str, Usage], list[str]]:
    """Run the scenarios in closed loop; usage per service (+ 'null', 'simulator')."""
    import os

    loaded = [load_scenario(find_scenario(name)) for name in scenarios]
    verdicts: list[str] = []
    with closed_loop(out_dir / "cost-run", log=sys.stdout if log else None) as loop:
        null = start_null_service(loop)
        try:
            pids = {s: loop.pid(s) for s in SERVICES}
            pids["null"] = null.pid
            pids["simulator"] = os.getpid()
            sampler = ProcSampler(pids).start()
            for sc in loaded:
                if log:
                    print(f"  running {sc.name} ({sc.duration_s:.0f} s) ...", flush=True)
                result = loop.sim.run(sc)
                verdicts.append(f"{sc.name}: {'PASS' if result.verdict.passed else 'FAIL'} "
                                f"({result.verdict.outcome})")
                loop.sim.wait_settled(SETTLE_TIMEOUT_S)
            usage = sampler.stop()
        finally:
            stop_processes([null])
    return usage, verdicts


def figures_from(usage: dict[str, Usage]) -> list[Figure]:
    null = usage["null"]
    figs: list[Figure] = []
    for name in SERVICES:
        u = usage[name]
        target = CPU_TARGET_PCT.get(name)
        figs.append(Figure(
            "cost", f"{name} CPU", round(u.cpu_pct, 2), "% of a core",
            baseline="null service (Zenoh session, every key, no work)",
            baseline_value=round(null.cpu_pct, 2),
            target=f"< {target:g}%" if target else "",
            target_met=(u.cpu_pct < target) if target else None,
            note="renders the simulated scene: not a target" if name == "camera" else ""))
    for name in SERVICES:
        p = usage[name].peak
        figs.append(Figure(
            "cost", f"{name} RSS max", round(p.rss / MB, 1), "MB",
            baseline="null service", baseline_value=round(null.rss_max / MB, 1),
            target=f"< {RSS_TARGET_MB:g} MB", target_met=p.rss / MB < RSS_TARGET_MB,
            note=(f"at peak: PSS {p.pss / MB:.0f} MB, anonymous {p.anon / MB:.0f} MB, "
                  f"shared memory (Zenoh SHM pool, shared with receivers) "
                  f"{p.shmem / MB:.0f} MB")))
    return figs


def run(quick: bool, out_dir: Path) -> list[Figure]:
    usage, verdicts = measure(QUICK_SCENARIOS if quick else FULL_SCENARIOS, out_dir)
    figs = figures_from(usage)
    sim = usage["simulator"]
    figs.append(Figure("cost", "simulator + benchmark CPU (context)", round(sim.cpu_pct, 2),
                       "% of a core", note="; ".join(verdicts)))
    return figs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_cost", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="one scenario instead of three")
    parser.add_argument("--out", default="out/bench")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    figs = run(args.quick, out)
    from benchmarks.report import print_table

    print_table(figs, sys.stdout)
    (out / "bench_cost.json").write_text(json.dumps(
        {"machine": machine_info(), "figures": [f.to_json() for f in figs]}, indent=1))
    print(f"({time.monotonic() - t0:.0f} s; {out / 'bench_cost.json'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
