"""`aeb demo`: the whole stack braking for simulated obstacles, on a machine with no
hardware. A SIMULATION of the vehicle, the ARS408 radar (real CAN frames on a pty that
the radar service opens as an slcan USB-CAN adapter), the camera (frames rendered from
the same geometry and calibration) and the brake actuator (the simulated actuator on a
pty). The stack under test is the real one, each service in its own process behind a
Zenoh router, exactly as `aeb up` starts it.

    aeb demo                                   # the demo scenarios
    aeb demo --scenarios all                   # every scenario in tools/sim/scenarios
    aeb demo --scenarios pedestrian_crossing_20kph,no_threat_parked_cars_30kph
    aeb demo --list

Prints live progress and a summary per scenario, and writes a timeline plot per scenario
(range, speed, TTC, decision and brake state, brake command and position) under --out.
Exit code: 0 when every scenario passed, 1 when one failed, 2 when the stack could not
be started.
"""

import argparse
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import IO, Any

import numpy as np

from aeb_radar_camera.common.bus import Bus, BusError
from aeb_radar_camera.common.config.loader import ConfigError
from aeb_radar_camera.common.keys import FUSION_BRAKE_CMD, FUSION_TARGETS
from aeb_radar_camera.common.log import add_log_level, setup_logging
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.tools.ab.compare import Comparator, render
from aeb_radar_camera.tools.ab.feeder import Feeder
from aeb_radar_camera.tools.sim.latency import chain_latencies_ns
from aeb_radar_camera.tools.sim.plot import plot_timeline
from aeb_radar_camera.tools.sim.radar_feed import RadarFeed
from aeb_radar_camera.tools.sim.runner import RunResult
from aeb_radar_camera.tools.sim.scenario import (
    DEMO_SCENARIOS,
    Scenario,
    all_scenarios,
    load_scenario,
    pick_scenarios,
)
from aeb_radar_camera.tools.sim.session import SETTLE_TIMEOUT_S, StackStartError, closed_loop
from aeb_radar_camera.tools.sim.stack import FUSION_CONFIG
from aeb_radar_camera.tools.sim.verdict import SUMMARY_HEADER, Sample, summary_line


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb demo", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenarios", default=",".join(DEMO_SCENARIOS),
                        help="comma-separated names or files, or 'all'")
    parser.add_argument("--out", default="out/demo", help="plots, summary and logs go here")
    parser.add_argument("--port", type=int, default=0,
                        help="router port on 127.0.0.1 (default: a free one)")
    parser.add_argument("--camera-fps", type=float, default=30.0)
    parser.add_argument("--radar-mode", choices=["scenario", "objects", "clusters"],
                        default="scenario", help="override the scenarios' radar output mode")
    parser.add_argument("--candidate", action="store_true",
                        help="also run the candidate fusion instance (deploy/fusion-candidate"
                             ".toml) in shadow mode and print the A/B report at the end")
    parser.add_argument("--fusion-config", type=Path, default=FUSION_CONFIG,
                        help="the followed fusion instance's config (default: the shipped "
                             "deploy/fusion.toml; e.g. deploy/fusion-paper.toml); the brake "
                             "follows its instance")
    parser.add_argument("--raw-can", action="store_true",
                        help="the radar also publishes its raw CAN frames (to record them "
                             "with `aeb record` for `aeb rerun radar`)")
    parser.add_argument("--list", action="store_true", help="list the scenarios and exit")
    add_log_level(parser, "WARNING")
    return parser.parse_args(argv)


class Progress:
    """One status line per scenario: redrawn on a terminal, a line a second otherwise."""

    def __init__(self, out: IO[str], name: str) -> None:
        self.out = out
        self.name = name
        self.tty = out.isatty()
        self._last = 0.0

    def __call__(self, s: Sample) -> None:
        now = time.monotonic()
        if now - self._last < (0.2 if self.tty else 1.0):
            return
        self._last = now
        gap = "-" if s.gap_m is None else f"{s.gap_m:5.1f} m"
        ttc = "-" if s.ttc_s is None else f"{s.ttc_s:4.1f} s"
        text = (f"  t {s.t_s:4.1f} s  speed {s.ego_speed_mps * 3.6:4.1f} km/h  gap {gap}  "
                f"TTC {ttc}  fusion {s.decision or '-':<7}  brake {s.brake_state or '-':<8}"
                f"  actuator {s.position_pct:5.1f}%")
        if self.tty:
            self.out.write("\r" + text + "\x1b[K")
        else:
            self.out.write(text + "\n")
        self.out.flush()

    def done(self) -> None:
        if self.tty:
            self.out.write("\n")


def run_demo(args: argparse.Namespace, scenarios: list[Scenario], out: Path) -> int:
    print("AEB demo: a closed-loop SIMULATION. Simulated: the vehicle, the ARS408 radar (CAN "
          "frames on a pty),\nthe camera (rendered frames) and the brake actuator (on a pty). "
          "Real: the router and the\nradar, camera, fusion and brake services, each in its "
          f"own process. Logs: {out / 'stack.log'}\n", flush=True)
    # no watchdog: the stack's teardown waits for its processes and must not be cut off
    stop = stop_event_on_signals(grace_s=None)
    results: list[RunResult] = []
    ab: Feeder | None = None
    feed: RadarFeed | None = None
    actuator: Any = None
    try:
        with closed_loop(out, args.port, args.camera_fps, args.candidate,
                         log=sys.stdout, fusion_config=args.fusion_config,
                         raw_can=args.raw_can) as loop:
            ab = start_ab(loop.bus) if args.candidate else None
            sim = loop.sim
            for i, sc in enumerate(scenarios, 1):
                if stop.is_set():
                    break
                if args.radar_mode != "scenario":
                    import msgspec

                    sc = msgspec.structs.replace(sc, radar=msgspec.structs.replace(
                        sc.radar, mode=args.radar_mode))
                print(f"[{i}/{len(scenarios)}] {sc.name} ({sc.kind.value}): "
                      f"{' '.join(sc.description.split())}", flush=True)
                progress = Progress(sys.stdout, sc.name)
                sim.on_sample = progress
                result = sim.run(sc)
                sim.on_sample = None
                progress.done()
                results.append(result)
                v = result.verdict
                plot = plot_timeline(result.samples, v, out / f"{sc.name}.png")
                print(f"  -> {'PASS' if v.passed else 'FAIL'}: {v.outcome}; plot {plot}",
                      flush=True)
                if i < len(scenarios) and not sim.wait_settled(SETTLE_TIMEOUT_S):
                    print("  warning: the stack did not settle before the next run",
                          flush=True)
            feed, actuator = loop.feed, loop.actuator
    except StackStartError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    code = report(results, feed, actuator, out)
    if ab is not None:
        print("\n" + render(ab.comparator.report(), max_episodes=12))
    return code


def start_ab(bus: Bus) -> Feeder:
    """Pair primary's and candidate's outputs as they arrive (aeb ab-report's core)."""
    feeder = Feeder(Comparator("primary", "candidate"))
    for spec in (FUSION_TARGETS, FUSION_BRAKE_CMD):
        def on_raw(payload: bytes, key: str, rx_mono_ns: int, name: str = spec.name) -> None:
            feeder.feed(name, payload)

        for instance in ("primary", "candidate"):
            bus.subscribe_raw(spec, on_raw, instance=instance)
    return feeder


def report(results: list[RunResult], feed: RadarFeed | None, actuator: Any, out: Path) -> int:
    print("\n" + SUMMARY_HEADER)
    for r in results:
        print(summary_line(r.verdict))
    lat: list[float] = []
    if feed is not None:
        ends = [c.last_write_mono_ns for c in feed.cycles()]
        lines = [r.t_ns for r in actuator.commands_since(0)]
        lat = [x / 1e6 for x in chain_latencies_ns(ends, lines)]
        if lat:
            print(f"\nradar-to-brake latency (last CAN frame of a cycle -> command line on the "
                  f"actuator), {len(lat)} of {len(ends)} cycles: p50 {np.percentile(lat, 50):.2f}"
                  f" ms, p99 {np.percentile(lat, 99):.2f} ms")
    passed = sum(r.verdict.passed for r in results)
    print(f"\n{passed} of {len(results)} scenarios passed; plots and summary in {out}/")
    summary = {"scenarios": [asdict(r.verdict) | {"kind": r.verdict.kind.value}
                             for r in results],
               "latency_ms": {"n": len(lat),
                              "p50": float(np.percentile(lat, 50)) if lat else None,
                              "p99": float(np.percentile(lat, 99)) if lat else None}}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return 0 if results and passed == len(results) else 1


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging("demo", args.log_level)
    if args.list:
        for path in all_scenarios():
            sc = load_scenario(path)
            mark = "*" if sc.name in DEMO_SCENARIOS else " "
            print(f"{mark} {sc.name:<44} {sc.kind.value:<9} {' '.join(sc.description.split())}")
        print("\n* in the default demo set")
        return 0
    try:
        scenarios = pick_scenarios(args.scenarios)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)
    try:
        return run_demo(args, scenarios, out)
    except (BusError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
