"""`aeb up`: start a local Zenoh router and the services of a process table, each in its
own process; restart crashed services with backoff; prefix every output line with the
process's name; stop everything on Ctrl-C or SIGTERM.

    aeb up                                   # deploy/single-host.toml
    aeb up --table deploy/ecu-a.toml         # one ECU's share
    aeb up --only radar,camera               # some services (and the table's router)
    aeb up --check                           # validate and print the commands
"""

import argparse
import shlex
import sys
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager

from common.config.loader import ConfigError
from common.cpu_latency import CpuLatencyRefused, cpu_latency
from common.resources import SINGLE_HOST_TABLE
from common.service import stop_event_on_signals
from tools.launch.supervisor import LinePrinter, Supervisor
from tools.launch.table import load_table, resolve_launches


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb up", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--table", "-t", default=str(SINGLE_HOST_TABLE),
                        help="process table (TOML), default: the shipped deploy/single-host.toml")
    parser.add_argument("--only", default="",
                        help="comma-separated service names to start (router still starts)")
    parser.add_argument("--no-router", action="store_true",
                        help="do not start the table's router (one runs elsewhere)")
    parser.add_argument("--check", action="store_true",
                        help="validate the table, print the commands, start nothing")
    parser.add_argument("--colour", choices=["auto", "always", "never"], default="auto")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Returns 0 after a requested stop, 1 when every process ended and one failed, and 2
    for an invalid table (named file and field on stderr)."""
    args = parse_args(argv)
    only = {n.strip() for n in args.only.split(",") if n.strip()} or None
    try:
        table, workdir = load_table(args.table)
        launches = resolve_launches(table, workdir, args.table, only, not args.no_router)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if not launches:
        print(f"error: {args.table}: nothing to start", file=sys.stderr)
        return 2
    if args.check:
        for launch in launches:
            env = " ".join(f"{k}={shlex.quote(v)}" for k, v in launch.env.items())
            print(f"{launch.name}: {env + ' ' if env else ''}{shlex.join(launch.argv)}"
                  f"  [restart={launch.restart.value}]")
        return 0
    colour = {"auto": None, "always": True, "never": False}[args.colour]
    printer = LinePrinter(sys.stdout, ["up", *(launch.name for launch in launches)], colour)
    # no watchdog: the supervisor escalates to SIGKILL itself (each child's stop_grace_s)
    stop = stop_event_on_signals(grace_s=None)
    supervisor = Supervisor(launches, printer)
    supervisor.say(f"table {args.table}: {', '.join(launch.name for launch in launches)}")
    with held_cpu_latency(table.cpu_latency_us, supervisor.say):
        return supervisor.run(stop)


@contextmanager
def held_cpu_latency(max_us: int | None, say: Callable[[str], None],
                     device: str | None = None) -> Iterator[None]:
    """The table's PM QoS request for the `with` block. Refused (not root, no such
    device), the stack runs all the same: it is said once, as a real-time refusal is."""
    with ExitStack() as held:
        if max_us is not None:
            try:
                held.enter_context(cpu_latency(max_us, device))
                say(f"cpu_latency_us={max_us}: no CPU idle state with a longer exit "
                    "latency while the table runs")
            except CpuLatencyRefused as exc:
                say(f"cpu_latency_us={max_us} refused, the machine's idle states stay: {exc}")
        yield


if __name__ == "__main__":
    sys.exit(main())
