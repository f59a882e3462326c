"""Joining the bus from a tool (`aeb monitor`, `echo`, `hz`, `calib-capture`,
`ab-report`, `record`, `replay`, `evidence`, `foxglove`): the options every bus tool
shares (where the router is, which vehicle, an optional Zenoh config, how long to wait
for the router, the log level), and a session opened so that Ctrl-C and SIGTERM work
while no router answers yet.

`zenoh.open` blocks until a router is reachable, and a signal handler only runs once it
returns; so the session is opened in a helper thread while the main thread waits on the
stop event (common/bus.py), which logs the wait with the endpoints.
"""

import argparse
import logging
import os
import sys
import threading
import time
from collections.abc import Callable

from aeb_radar_camera.common.bus import Bus, BusError
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.log import add_log_level

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
_LOOPBACK = ("127.", "localhost", "[::1]")

_log = logging.getLogger("bus")


def positive(text: str) -> float:
    """An argparse type: a number > 0 (a period, a rate); argparse exits 2 otherwise."""
    value = _number(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text!r}: must be greater than 0")
    return value


def non_negative(text: str) -> float:
    """An argparse type: a number >= 0 (a duration, a timeout)."""
    value = _number(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: must not be negative")
    return value


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: not a number") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"{text!r}: not a finite number")
    return value


def add_bus_args(parser: argparse.ArgumentParser, connect_timeout_s: float = 10.0,
                 listen: bool = False) -> None:
    """`--connect`, `--vehicle`, `--zenoh-config`, `--connect-timeout` (default
    `connect_timeout_s`; 0: wait as long as it takes, for a recorder started before the
    stack) and `--log-level`; `listen`: also `--listen`, to be the router."""
    parser.add_argument("--connect", action="append", default=None, metavar="ENDPOINT",
                        help=f"router endpoint (repeatable), default {DEFAULT_ENDPOINT}")
    parser.add_argument("--vehicle", default="ego")
    parser.add_argument("--zenoh-config", default="", help="Zenoh JSON5 client config")
    parser.add_argument("--connect-timeout", type=non_negative, default=connect_timeout_s,
                        help="give up when no router answers within this many seconds "
                             f"(0: wait as long as it takes; default {connect_timeout_s:g})")
    if listen:
        parser.add_argument("--listen", action="append", default=None, metavar="ENDPOINT",
                            help="run as a Zenoh router listening here instead (a replay "
                                 "with a stack connecting to it)")
    add_log_level(parser, "WARNING")


def endpoints(args: argparse.Namespace) -> tuple[str, ...]:
    return tuple(args.connect or [DEFAULT_ENDPOINT])


def on_this_host(args: argparse.Namespace) -> bool:
    """Every endpoint is loopback: publishers share this host's monotonic clock."""
    return all(ep.split("/", 1)[-1].startswith(_LOOPBACK) for ep in endpoints(args))


def bus_settings(args: argparse.Namespace) -> ZenohSettings:
    """Raises ValueError for a malformed endpoint."""
    listen = tuple(getattr(args, "listen", None) or ())
    if listen:
        return ZenohSettings(mode=ZenohMode.ROUTER, connect=tuple(args.connect or ()),
                             listen=listen, config_file=args.zenoh_config)
    overrides = ({"connect/timeout_ms": int(args.connect_timeout * 1000)}
                 if args.connect_timeout > 0 else {})
    return ZenohSettings(mode=ZenohMode.CLIENT, connect=endpoints(args),
                         config_file=args.zenoh_config, overrides=overrides)


def open_bus(args: argparse.Namespace, source: str, stop: threading.Event) -> Bus:
    """The bus. Prints and raises SystemExit(2) when the settings are invalid or the
    session cannot be opened (no router within `--connect-timeout`); exits the process
    (code 0) when `stop` is set before a router answered (nothing was done yet)."""
    try:
        settings = bus_settings(args)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from exc
    try:
        bus = Bus.open_until_stopped(settings, args.vehicle, source, stop, _log)
    except BusError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from exc
    if bus is None:
        print("stopped before the bus was reached", file=sys.stderr, flush=True)
        # The opener is stuck in zenoh.open and would hold the interpreter's exit.
        sys.stderr.flush()
        sys.stdout.flush()
        os._exit(0)
    return bus


def run_until(stop: threading.Event, duration_s: float | None,
              failed: Callable[[], bool] = lambda: False) -> None:
    """Until a signal (`stop`), `duration_s` (None: no limit) or `failed()`."""
    end = None if duration_s is None else time.monotonic() + duration_s
    while not stop.wait(0.5 if end is None else max(0.0, min(0.5, end - time.monotonic()))):
        if failed() or (end is not None and time.monotonic() >= end):
            return
