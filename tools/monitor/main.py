"""`aeb monitor`: watch a running stack over the network.

Subscribes (through the key registry) to every key of one vehicle and shows, refreshed:
each service's liveliness, the rate and latency of every key, the brake's state, each
fusion instance's last command and verified targets, the radar's tracks and status, the
camera's status, and the simulator's ground truth when one runs.

    aeb monitor --connect tcp/192.168.10.1:7447          # live, refreshing table
    aeb monitor --once --duration 5                      # one table after 5 s (scripts)
    aeb monitor --once --json                            # the same as JSON
    aeb monitor --zenoh-config deploy/zenoh/secure/client-monitor.json5 \
        --connect tls/192.168.10.1:7447                  # secure profile
"""

import argparse
import json
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.keys import KeySpec
from aeb_radar_camera.common.log import setup_logging
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.tools.bus import (
    add_bus_args,
    endpoints,
    non_negative,
    on_this_host,
    open_bus,
    positive,
)
from aeb_radar_camera.tools.keys import MESSAGE_KEYS
from aeb_radar_camera.tools.monitor.state import MonitorState
from aeb_radar_camera.tools.monitor.view import render_text, snapshot

_CLEAR = "\x1b[H\x1b[2J"


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb monitor", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_bus_args(parser)
    parser.add_argument("--once", action="store_true",
                        help="collect for --duration (default 3 s), print once, exit")
    parser.add_argument("--duration", type=non_negative, default=None,
                        help="stop after this many seconds")
    parser.add_argument("--interval", type=positive, default=1.0, help="refresh period (s)")
    parser.add_argument("--json", action="store_true", help="print snapshots as JSON lines")
    parser.add_argument("--plain", action="store_true",
                        help="append snapshots instead of redrawing (default when not a TTY)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--same-host", dest="same_host", action="store_true", default=None,
                       help="publishers share this host's monotonic clock (hop latency)")
    where.add_argument("--remote", dest="same_host", action="store_false")
    return parser.parse_args(argv)


def subscribe_all(bus: Bus, state: MonitorState, lock: threading.Lock) -> list[Any]:
    """One subscription per message key of the registry and the simulator's ground truth
    (every parameter a wildcard)."""
    subs = []
    for spec in MESSAGE_KEYS:
        def on_msg(msg: Any, key: str, spec: KeySpec[Any] = spec) -> None:
            rx_mono, rx_wall = mono_ns(), wall_ns()
            with lock:
                state.observe(spec, key, msg, rx_mono, rx_wall)

        subs.append(bus.subscribe(spec, on_msg))

    def on_health(service: str, instance: str, alive: bool) -> None:
        with lock:
            state.on_health(service, instance, alive, mono_ns())

    subs.append(bus.subscribe_health(on_health))
    return subs


def main(argv: list[str] | None = None) -> int:
    """Returns 0; raises SystemExit(2) when the bus cannot be opened (bad endpoint, no
    router in time)."""
    args = parse_args(argv)
    setup_logging("monitor", args.log_level)
    connect = endpoints(args)
    same_host = on_this_host(args) if args.same_host is None else args.same_host
    stop = stop_event_on_signals()
    bus = open_bus(args, "monitor", stop)
    state = MonitorState(same_host)
    lock = threading.Lock()
    endpoint = ",".join(connect)
    redraw = sys.stdout.isatty() and not (args.plain or args.json or args.once)

    def show() -> None:
        with lock:
            state.decode_errors = bus.decode_errors.snapshot()
            snap = snapshot(state, mono_ns(), args.vehicle, endpoint)
        if args.json:
            print(json.dumps(snap), flush=True)
            return
        text = render_text(snap)
        print((_CLEAR + text) if redraw else text + "\n", flush=True)

    with bus:
        subscribe_all(bus, state, lock)
        if args.once:
            stop.wait(3.0 if args.duration is None else args.duration)
            show()
            return 0
        run_until(stop, args.duration, args.interval, show)
    return 0


def run_until(stop: threading.Event, duration: float | None, interval: float,
              show: Callable[[], None]) -> None:
    end = None if duration is None else time.monotonic() + duration
    while not stop.is_set():
        left = interval if end is None else min(interval, end - time.monotonic())
        if left > 0:
            stop.wait(left)
        show()
        if end is not None and time.monotonic() >= end:
            break


if __name__ == "__main__":
    sys.exit(main())
