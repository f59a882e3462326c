"""What every service's `main` shares: arguments, config loading with CLI overrides,
logging set-up, and a stop event wired to SIGINT/SIGTERM."""

import argparse
import signal
import threading
from typing import TypeVar

import msgspec

from common.config.base import ServiceConfig
from common.config.loader import load_config_or_exit

C = TypeVar("C", bound=ServiceConfig)


def service_argparser(name: str, description: str) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=f"aeb {name}", description=description)
    parser.add_argument("--config", "-c", help="service TOML file (defaults when omitted)")
    parser.add_argument(
        "--connect", action="append", default=None, metavar="ENDPOINT",
        help="Zenoh endpoint to connect to (repeatable), overrides the config's zenoh.connect",
    )
    parser.add_argument("--vehicle", help="vehicle id, overrides the config's vehicle")
    parser.add_argument("--log-level", choices=["DEBUG", "INFO", "WARNING", "ERROR"])
    return parser


def load_service_config(args: argparse.Namespace, config_type: type[C]) -> C:
    """The validated config with command-line overrides applied; exits 2 when invalid."""
    cfg = load_config_or_exit(args.config, config_type)
    if args.connect:
        cfg = msgspec.structs.replace(
            cfg, zenoh=msgspec.structs.replace(cfg.zenoh, connect=tuple(args.connect))
        )
    if args.vehicle:
        cfg = msgspec.structs.replace(cfg, vehicle=args.vehicle)
    if args.log_level:
        from common.config.base import LogLevel

        cfg = msgspec.structs.replace(
            cfg, log=msgspec.structs.replace(cfg.log, level=LogLevel(args.log_level))
        )
    return cfg


def stop_event_on_signals() -> threading.Event:
    """An event set by SIGINT or SIGTERM (main thread only)."""
    stop = threading.Event()

    def handler(signum: int, frame: object) -> None:
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop
