"""Joining the bus from a recording tool (`aeb record`, `replay`, `evidence`,
`foxglove`): the bus tools' options, and a session opened so that Ctrl-C works while no
router answers yet.

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

from common.bus import Bus, BusError
from common.config.base import ZenohMode, ZenohSettings
from common.log import add_log_level
from tools.bus_args import add_bus_args, endpoints

_log = logging.getLogger("bus")


def add_bus_arguments(parser: argparse.ArgumentParser, listen: bool = False) -> None:
    """The bus tools' options (tools/bus_args.py), waiting for the router as long as it
    takes unless `--connect-timeout` says otherwise (a recorder is started before the
    stack); `listen`: also `--listen`, to be the router."""
    add_bus_args(parser)
    parser.set_defaults(connect_timeout=0.0)
    if listen:
        parser.add_argument("--listen", action="append", default=None, metavar="ENDPOINT",
                            help="run as a Zenoh router listening here instead (a replay "
                                 "with a stack connecting to it)")
    add_log_level(parser, "WARNING")


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
    session cannot be opened; exits the process (code 0) when `stop` is set before a
    router answered (nothing was done yet)."""
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
