"""The lockstep loop measured: each scenario's verdict and first BRAKE (over several loop
seeds), beside an `aeb demo` run's (its summary.json), and what a simulated second costs
and where that time goes. A SIMULATION measurement.

    python -m aeb_radar_camera.tools.grid.measure               # the demo's scenarios
    python -m aeb_radar_camera.tools.grid.measure --demo-summary out/demo/summary.json --seeds 0-4
    python -m aeb_radar_camera.tools.grid.measure --fusion-config deploy/fusion-paper.toml \
        --json out/x.json

Wall times are this host's, one run at a time (`--workers 1`, the default: runs in
parallel share the cores and the figures with them); CPU times (the process's, all its
threads) move less with the host's load.
"""

import argparse
import json
import sys
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from aeb_radar_camera.common.config.loader import ConfigError
from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.tools.grid.delays import Delays
from aeb_radar_camera.tools.grid.pool import Case, Outcome, print_progress, run_cases
from aeb_radar_camera.tools.grid.profile import PARTS
from aeb_radar_camera.tools.sim.scenario import DEMO_SCENARIOS, pick_scenarios


def parse_seeds(text: str) -> list[int]:
    """"0-4" or "0,3,7". Raises ValueError."""
    if "-" in text:
        lo, hi = (int(x) for x in text.split("-", 1))
        return list(range(lo, hi + 1))
    return [int(x) for x in text.split(",") if x]


def _fmt(t: float | None) -> str:
    return "-" if t is None else f"{t:.2f}"


def rows(outcomes: list[Outcome], demo: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """Per scenario: the lockstep runs' outcomes, first BRAKE times and speed."""
    by_name: dict[str, list[Outcome]] = {}
    for o in outcomes:
        by_name.setdefault(o.case.scenario.name, []).append(o)
    out = []
    for name, runs in by_name.items():
        done = [o.result for o in runs if o.result is not None]
        brakes = [r.verdict.first_brake_t_s for r in done]
        sim_s = sum(r.simulated_s for r in done)
        parts = {p: sum(r.profile.seconds[p] for r in done) for p in PARTS}
        parts["fusion_own"] = sum(r.profile.fusion_own_s for r in done)
        live = demo.get(name, {})
        known = [b for b in brakes if b is not None]
        out.append({
            "scenario": name, "runs": len(runs), "errors": [o.error for o in runs if o.error],
            "outcomes": sorted({r.verdict.outcome for r in done}),
            "passed": sum(r.verdict.passed for r in done),
            "first_brake_s": brakes,
            "demo_outcome": live.get("outcome"), "demo_first_brake_s": live.get("first_brake_t_s"),
            "delta_s": (float(np.median(known)) - live["first_brake_t_s"]
                        if known and live.get("first_brake_t_s") is not None else None),
            "wall_per_sim_s": sum(r.wall_s for r in done) / sim_s if sim_s else None,
            "cpu_per_sim_s": sum(r.cpu_s for r in done) / sim_s if sim_s else None,
            "simulated_s": sim_s,
            "parts_per_sim_s": {p: v / sim_s for p, v in parts.items()} if sim_s else {},
            "frames_rendered": sum(r.profile.frames_rendered for r in done),
            "frames_captured": sum(r.profile.frames_captured for r in done),
        })
    return out


def print_table(table: list[dict[str, Any]], demo: bool) -> None:
    head = f"{'scenario':<42} {'lockstep':<34} {'1st BRAKE (s)':<22}"
    if demo:
        head += f" {'aeb demo':<24} {'delta':>6}"
    print(head + f" {'wall/sim':>8} {'cpu/sim':>7}  render jpeg fusion-own other "
                 "(ms wall per simulated s)")
    for r in table:
        brakes = [b for b in r["first_brake_s"] if b is not None]
        when = (f"{min(brakes):.2f}-{max(brakes):.2f}" if len(set(brakes)) > 1
                else _fmt(brakes[0]) if brakes else "-")
        if brakes and len(brakes) < len(r["first_brake_s"]):
            when += f" ({len(brakes)}/{len(r['first_brake_s'])})"
        line = f"{r['scenario']:<42} {'; '.join(r['outcomes'])[:34]:<34} {when:<22}"
        if demo:
            line += (f" {(r['demo_outcome'] or '-')[:24]:<24} "
                     f"{'-' if r['delta_s'] is None else format(r['delta_s'], '+.2f'):>6}")
        p = {k: 1000 * v for k, v in r["parts_per_sim_s"].items()}
        codecs = p.get("jpeg_encode", 0) + p.get("jpeg_decode", 0) + p.get("depth_codec", 0)
        other = 1000 * (r["wall_per_sim_s"] or 0) - p.get("fusion", 0.0)
        line += (f" {r['wall_per_sim_s'] or 0:8.3f} {r['cpu_per_sim_s'] or 0:7.3f}"
                 f"  {p.get('render', 0):6.0f} {codecs:4.0f}"
                 f" {p.get('fusion_own', 0):10.0f} {other:5.0f}")
        print(line)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m aeb_radar_camera.tools.grid.measure", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenarios", default=",".join(DEMO_SCENARIOS),
                        help="comma-separated names or files, or 'all'")
    parser.add_argument("--fusion-config", type=Path, default=DEPLOY / "fusion.toml")
    parser.add_argument("--seeds", default="0", help="loop seeds: 0-4 or 0,3,7")
    parser.add_argument("--demo-summary", type=Path, default=None,
                        help="an `aeb demo` run's summary.json to compare with")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--json", type=Path, default=None, help="write the table here")
    args = parser.parse_args(argv)
    try:
        scenarios = pick_scenarios(args.scenarios)
        seeds = parse_seeds(args.seeds)
    except (ConfigError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    demo: dict[str, dict[str, Any]] = {}
    if args.demo_summary is not None:
        demo = {s["scenario"]: s for s in json.loads(args.demo_summary.read_text())["scenarios"]}
    cases = [Case(sc, args.fusion_config, loop_seed=seed, name=f"{sc.name} (seed {seed})")
             for sc in scenarios for seed in seeds]
    outcomes = run_cases(cases, args.workers, print_progress())
    table = rows(outcomes, demo)
    print()
    print_table(table, bool(demo))
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"fusion_config": str(args.fusion_config),
                                         "seeds": seeds, "delays": asdict(Delays()),
                                         "rows": table}, indent=1))
    return 1 if any(o.error for o in outcomes) else 0


if __name__ == "__main__":
    sys.exit(main())
