"""`aeb faults`: inject faults into the running stack and check each required response
and its time bound; `aeb faults fuzz`: the long fuzz run (tools/faults/fuzz.py).

    aeb faults                    # quick: one injection of each fault (CI)
    aeb faults --soak             # at least 100 injections of each, one stack throughout
    aeb faults --rounds 5 --only SIGKILL,intruder
    aeb faults --soak --realtime-priority 20   # the services at SCHED_FIFO, as deployed
    aeb faults fuzz [--scale 0.1]

The stack is the closed loop of `aeb demo` (router, radar, camera, fusion, brake, started
by the launcher of `aeb up`, restarted by it when killed) on the SIMULATED radar link,
camera and actuator. Writes faults.md, faults.json and faults.png under --out. Exit code
0 when every injection got its response within bound, 1 otherwise, 2 when the stack
could not start.
"""

import argparse
import logging
import sys
import time
from pathlib import Path

from aeb_radar_camera.common.bus import BusError
from aeb_radar_camera.common.config.loader import ConfigError
from aeb_radar_camera.common.log import add_log_level, setup_logging
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.tools.faults import harness, report
from aeb_radar_camera.tools.sim.session import StackStartError

SOAK_ROUNDS = 100
SOAK_BUDGET_S = 40 * 60


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="aeb faults", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--soak", action="store_true",
                   help=f"{SOAK_ROUNDS} rounds (every fault each round), within "
                        f"--time-budget-s")
    p.add_argument("--rounds", type=int, help="rounds to run (quick: 1, soak: 100)")
    p.add_argument("--time-budget-s", type=float,
                   help=f"start no new round after this long (soak: {SOAK_BUDGET_S} s)")
    p.add_argument("--only", help="comma-separated parts of fault names to run")
    p.add_argument("--skip", help="comma-separated parts of fault names not to run")
    p.add_argument("--combine", nargs="+", metavar="FAULTS_JSON",
                   help="no run: one table from the faults.json of several runs (e.g. "
                        "two groups of faults run one after the other) into --out")
    p.add_argument("--link", choices=["auto", "relay"], default="auto",
                   help="the cut link: fusion in its own network namespace (auto, where "
                        "it can be made; else) or behind a loopback TCP relay")
    p.add_argument("--realtime-priority", type=int, default=0, metavar="N",
                   help="SCHED_FIFO at N for the router and the latency path of radar, "
                        "fusion and brake, as deployed (deploy/*.toml: 20), and at N - 10 "
                        "for the simulated hardware's threads (a sensor does not wait for "
                        "a CPU); 0: normal scheduling. Needs root or an RLIMIT_RTPRIO of N")
    p.add_argument("--seed", type=int, default=19)
    p.add_argument("--out", default="out/faults")
    add_log_level(p, "WARNING")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args_in = sys.argv[1:] if argv is None else argv
    if args_in[:1] == ["fuzz"]:
        from aeb_radar_camera.tools.faults import fuzz
        return fuzz.main(args_in[1:])
    args = parse_args(args_in)
    setup_logging("faults", args.log_level)
    # the harness's own session sees the garbage it floods: its decode warnings are noise
    logging.getLogger("bus").setLevel(logging.ERROR)
    rounds = args.rounds or (SOAK_ROUNDS if args.soak else 1)
    budget = args.time_budget_s or (SOAK_BUDGET_S if args.soak else None)
    mode = "soak" if args.soak else ("quick" if rounds == 1 else f"{rounds} rounds")
    out = Path(args.out)
    if args.combine:
        records, info = report.combine([Path(p) for p in args.combine])
        md, js, png = report.write(out, records, info)
        print(md.read_text())
        return 0
    only = [o.strip() for o in args.only.split(",")] if args.only else None
    skip = [o.strip() for o in args.skip.split(",")] if args.skip else None
    print(f"aeb faults ({mode}): the real stack on a SIMULATED vehicle, radar link, camera "
          f"and actuator; logs in {out / 'stack.log'}", flush=True)
    t0 = time.monotonic()
    # SIGINT / SIGTERM: the current injection ends, the stack stops, the table is written
    # (no watchdog: the stack's teardown waits for its processes)
    stop = stop_event_on_signals(grace_s=None)
    try:
        records, info = harness.run(out, rounds, mode, sys.stdout, budget, only, args.seed,
                                    link_kind=args.link, stop=stop, skip=skip,
                                    realtime_priority=args.realtime_priority)
    except (StackStartError, ConfigError, BusError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    md, js, png = report.write(out, records, info)
    print("\n" + md.read_text())
    print(f"{time.monotonic() - t0:.0f} s; {md}, {js}" + (f", {png}" if png else ""))
    ran = [r for r in records if r.outcomes]
    all_ok = bool(ran) and all(o.ok for r in ran for o in r.outcomes) and not info.stopped_early
    return 0 if all_ok else 1


if __name__ == "__main__":
    sys.exit(main())
