"""The options every bus tool shares (`aeb monitor`, `echo`, `hz`, `calib-capture`):
where the router is, which vehicle, an optional Zenoh client config, and how long to wait
for the router."""

import argparse
import sys

from common.bus import Bus, BusError
from common.config.base import ZenohMode, ZenohSettings

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
_LOOPBACK = ("127.", "localhost", "[::1]")


def add_bus_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--connect", action="append", default=None, metavar="ENDPOINT",
                        help=f"router endpoint (repeatable), default {DEFAULT_ENDPOINT}")
    parser.add_argument("--vehicle", default="ego")
    parser.add_argument("--zenoh-config", default="", help="Zenoh JSON5 client config")
    parser.add_argument("--connect-timeout", type=float, default=10.0,
                        help="give up when no router answers within this many seconds")


def endpoints(args: argparse.Namespace) -> tuple[str, ...]:
    return tuple(args.connect or [DEFAULT_ENDPOINT])


def on_this_host(args: argparse.Namespace) -> bool:
    """Every endpoint is loopback: publishers share this host's monotonic clock."""
    return all(ep.split("/", 1)[-1].startswith(_LOOPBACK) for ep in endpoints(args))


def open_tool_bus(args: argparse.Namespace, source: str) -> Bus:
    """A client session as the options say. Raises BusError (no router in time, bad
    config) or ValueError (a malformed endpoint)."""
    settings = ZenohSettings(
        mode=ZenohMode.CLIENT, connect=endpoints(args), config_file=args.zenoh_config,
        overrides={"connect/timeout_ms": int(args.connect_timeout * 1000)})
    return Bus.open(settings, args.vehicle, source)


def open_or_say(args: argparse.Namespace, source: str) -> Bus | None:
    """`open_tool_bus`, or None once the reason is printed (the tool exits with code 2)."""
    try:
        return open_tool_bus(args, source)
    except (BusError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return None
