"""`aeb up`: start a local Zenoh router and the services of a process table, each in its
own process; restart crashed services with backoff; prefix every output line with the
process's name; stop everything on Ctrl-C or SIGTERM.

    aeb up                                   # deploy/single-host.toml
    aeb up --table deploy/ecu-a.toml         # one ECU's share
    aeb up --only radar,camera               # some services (and the table's router)
    aeb up --check                           # validate every config as its service would
    aeb up --exec brake                      # run one process of the table in place of
                                             # the launcher (systemd units: aeb@.service)
"""

import argparse
import os
import shlex
import sys
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager

from aeb_radar_camera.common.config.loader import ConfigError
from aeb_radar_camera.common.cpu_latency import CpuLatencyRefused, cpu_latency
from aeb_radar_camera.common.log import add_log_level, setup_logging
from aeb_radar_camera.common.resources import SINGLE_HOST_TABLE
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.common.systemd import Watchdog
from aeb_radar_camera.tools.launch.check import check_all, reach_warnings
from aeb_radar_camera.tools.launch.supervisor import LinePrinter, Supervisor
from aeb_radar_camera.tools.launch.table import Launch, load_table, resolve_launches


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
                        help="validate the table and every process's config as the process "
                             "would at start, print the commands, start nothing")
    parser.add_argument("--exec", metavar="NAME", dest="exec_name",
                        help="replace this launcher by the table's process NAME (`router` or "
                             "a service): no supervision, for a systemd unit per process")
    parser.add_argument("--colour", choices=["auto", "always", "never"], default="auto")
    add_log_level(parser)
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Returns 0 after a requested stop, 1 when every process ended and one failed, and 2
    for an invalid table (named file and field on stderr)."""
    args = parse_args(argv)
    setup_logging("up", args.log_level or "INFO")
    only = {n.strip() for n in args.only.split(",") if n.strip()} or None
    try:
        table, workdir = load_table(args.table)
        launches = resolve_launches(table, workdir, args.table, only, not args.no_router,
                                    log_level=args.log_level)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if not launches:
        print(f"error: {args.table}: nothing to start", file=sys.stderr)
        return 2
    if args.exec_name:
        return exec_launch(launches, args.exec_name, args.table)
    if args.check:
        return check(launches)
    colour = {"auto": None, "always": True, "never": False}[args.colour]
    printer = LinePrinter(sys.stdout, ["up", *(launch.name for launch in launches)], colour)
    # no watchdog: the supervisor escalates to SIGKILL itself (each child's stop_grace_s)
    stop = stop_event_on_signals(grace_s=None)
    supervisor = Supervisor(launches, printer)
    supervisor.say(f"table {args.table}: {', '.join(launch.name for launch in launches)}")
    for warning in reach_warnings(launches):
        supervisor.say(f"WARNING {warning}")
    with held_cpu_latency(table.cpu_latency_us, supervisor.say):
        return supervisor.run(stop, Watchdog())


def check(launches: list[Launch]) -> int:
    """Print each process's command line and the verdict of its own `--check`; 2 when one
    rejects its configuration."""
    for launch in launches:
        env = " ".join(f"{k}={shlex.quote(v)}" for k, v in launch.env.items())
        print(f"{launch.name}: {env + ' ' if env else ''}{shlex.join(launch.argv)}"
              f"  [restart={launch.restart.value}]")
    failed = 0
    for result in check_all(launches):
        mark = {True: "ok", False: "INVALID", None: "--"}[result.ok]
        if result.ok and result.detail.startswith("WARNING"):
            mark = "WARNING"     # valid, but e.g. an insecure example key is accepted
        print(f"  {mark:<7} {result.name}: {result.detail}")
        failed += result.ok is False
    for warning in reach_warnings(launches):
        print(f"  WARNING {warning}")
    if failed:
        print(f"error: {failed} of {len(launches)} processes reject their configuration",
              file=sys.stderr)
        return 2
    return 0


def exec_launch(launches: list[Launch], name: str, table: str) -> int:
    """exec the process `name` as the launcher would start it (same argv, environment and
    working directory); returns 2 only when the table has no such process."""
    launch = next((launch for launch in launches if launch.name == name), None)
    if launch is None:
        print(f"error: {table}: no process {name!r} to exec; the table has "
              f"{', '.join(launch.name for launch in launches)}", file=sys.stderr)
        return 2
    sys.stdout.flush()
    os.chdir(launch.cwd)
    os.execve(launch.argv[0], list(launch.argv), {**os.environ, **launch.env})


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
