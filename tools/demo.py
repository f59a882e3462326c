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
import threading
import time
from dataclasses import asdict
from pathlib import Path
from typing import IO, Any

import numpy as np

from common.bus import Bus, BusError
from common.config.base import ZenohMode, ZenohSettings
from common.config.loader import ConfigError
from common.keys import FUSION_BRAKE_CMD, FUSION_TARGETS
from common.log import setup_logging
from common.service import stop_event_on_signals
from tools.ab.compare import Comparator, render
from tools.ab_report import Feeder
from tools.launch.supervisor import LinePrinter, Supervisor
from tools.launch.table import load_table, resolve_launches
from tools.sim.latency import chain_latencies_ns
from tools.sim.plot import plot_timeline
from tools.sim.radar_feed import RadarFeed
from tools.sim.runner import RunResult, SimActuatorView, Simulator
from tools.sim.scenario import RadarLook, Scenario, all_scenarios, find_scenario, load_scenario
from tools.sim.stack import REPO, SERVICES, TOKENS, StackConfigs, write_configs
from tools.sim.verdict import SUMMARY_HEADER, Sample, summary_line

DEMO_SCENARIOS = (
    "stationary_car_30kph",
    "cardboard_box_30kph",
    "pedestrian_standing_20kph",
    "pedestrian_crossing_20kph",
    "pedestrian_behind_parked_car_20kph",
    "bicycle_ahead_slow_20kph",
    "multi_object_25kph",
    "no_threat_parked_cars_30kph",
    "no_threat_pedestrian_walking_beside_20kph",
)
CANDIDATE_CONFIG = REPO / "deploy" / "fusion-candidate.toml"
START_TIMEOUT_S = 120.0
SETTLE_TIMEOUT_S = 60.0


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
    parser.add_argument("--list", action="store_true", help="list the scenarios and exit")
    return parser.parse_args(argv)


def free_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def pick_scenarios(spec: str) -> list[Scenario]:
    """Raises ConfigError naming an unknown or invalid scenario."""
    paths = all_scenarios() if spec == "all" else [
        find_scenario(name.strip()) for name in spec.split(",") if name.strip()]
    if not paths:
        raise ConfigError("no scenario selected")
    return [load_scenario(p) for p in paths]


def write_table(folder: Path, endpoint: str, configs: StackConfigs,
                candidate: bool = False) -> Path:
    """The demo's process table (the same launcher as `aeb up`)."""
    lines = [
        "# Written by aeb demo: the stack under simulation.",
        f'workdir = "{REPO}"', "stop_grace_s = 5.0", "",
        "[router]", f'listen = ["{endpoint}"]', "",
        "[zenoh]", f'connect = ["{endpoint}"]', "",
        "[restart]", 'mode = "never"', "",
    ]
    for name in SERVICES:
        lines += ["[[service]]", f'name = "{name}"', f'aeb = "{name}"',
                  f'config = "{configs.of(name)}"', ""]
    if candidate:
        lines += ["[[service]]", 'name = "fusion-candidate"', 'aeb = "fusion"',
                  f'config = "{CANDIDATE_CONFIG}"', ""]
    path = folder / "table.toml"
    path.write_text("\n".join(lines))
    return path


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


def wait_for_stack(bus: Bus, supervisor: Supervisor, timeout_s: float) -> str:
    """Empty once every service's liveliness token is up, else why not."""
    alive: dict[tuple[str, str], bool] = {}
    lock = threading.Lock()

    def on_health(service: str, instance: str, up: bool) -> None:
        with lock:
            alive[(service, instance)] = up

    bus.subscribe_health(on_health)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with lock:
            missing = [s for s in SERVICES if not alive.get(TOKENS[s], False)]
        if not missing:
            return ""
        dead = [c.name for c in supervisor.children if c.finished]
        if dead:
            return f"{', '.join(dead)} exited"
        time.sleep(0.05)
    return f"no liveliness token from {', '.join(missing)} within {timeout_s:.0f} s"


def tail(path: Path, n: int = 30) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-n:])
    except OSError:
        return ""


def run_demo(args: argparse.Namespace, scenarios: list[Scenario], out: Path) -> int:
    from services.brake.sim_actuator import SimActuator
    from services.radar.can_links import SlcanPtyLink

    run_dir = out / "run"
    run_dir.mkdir(parents=True, exist_ok=True)
    log_path = out / "stack.log"
    port = args.port or free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    print("AEB demo: a closed-loop SIMULATION. Simulated: the vehicle, the ARS408 radar (CAN "
          "frames on a pty),\nthe camera (rendered frames) and the brake actuator (on a pty). "
          "Real: the router and the\nradar, camera, fusion and brake services, each in its "
          f"own process. Logs: {log_path}\n", flush=True)
    stop = stop_event_on_signals()
    link = SlcanPtyLink()
    actuator, _pair = SimActuator.on_pty(run_dir / "actuator")
    actuator.start()
    configs = write_configs(run_dir, endpoint, str(run_dir / "actuator"), link.path,
                            camera_fps=args.camera_fps)
    log_file = open(log_path, "w")  # noqa: SIM115 (closed in finally)
    supervisor: Supervisor | None = None
    poller_stop = threading.Event()
    results: list[RunResult] = []
    feed: RadarFeed | None = None
    ab: Feeder | None = None
    try:
        table, workdir = load_table(write_table(run_dir, endpoint, configs, args.candidate))
        launches = resolve_launches(table, workdir, "demo")
        supervisor = Supervisor(launches, LinePrinter(
            log_file, ["up", *(launch.name for launch in launches)], colour=False))
        supervisor.start()
        sup = supervisor

        def poll() -> None:
            while not poller_stop.wait(0.1):
                sup.poll()

        threading.Thread(target=poll, name="supervise", daemon=True).start()
        print(f"starting router ({endpoint}) and {', '.join(SERVICES)} ...", flush=True)
        t0 = time.monotonic()
        settings = ZenohSettings(mode=ZenohMode.CLIENT, connect=(endpoint,))
        with Bus.open(settings, "ego", "sim") as bus:
            problem = wait_for_stack(bus, supervisor, START_TIMEOUT_S)
            if problem:
                print(f"error: the stack did not start: {problem}\n{tail(log_path)}",
                      file=sys.stderr)
                return 2
            print(f"all services up in {time.monotonic() - t0:.1f} s", flush=True)
            ab = start_ab(bus) if args.candidate else None
            feed = RadarFeed(link, RadarLook())
            sim = Simulator(bus, feed, SimActuatorView(actuator)).start()
            try:
                if not sim.wait_settled(SETTLE_TIMEOUT_S):
                    print(f"error: the stack never armed (fusion {sim.decision or 'silent'}, "
                          f"brake {sim.brake_state or 'silent'})\n{tail(log_path)}",
                          file=sys.stderr)
                    return 2
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
            finally:
                sim.stop()
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    finally:
        poller_stop.set()
        if supervisor is not None:
            supervisor.shutdown()
        link.close()
        actuator.stop()
        log_file.close()
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
    setup_logging("demo", "WARNING")
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
