"""What every service's `main` shares: arguments, config loading with command-line
overrides (`--set section.key=value` and the options that stand for one), logging
set-up, and a stop event wired to SIGINT/SIGTERM."""

import argparse
import os
import signal
import sys
import threading
from collections.abc import Mapping, Sequence
from typing import Any, TypeVar

from aeb_radar_camera.common.bus import BusError, zenoh_config
from aeb_radar_camera.common.config.base import ServiceConfig
from aeb_radar_camera.common.config.loader import load_config_or_exit
from aeb_radar_camera.common.config.overrides import Override, add_set_argument
from aeb_radar_camera.common.log import add_log_level

C = TypeVar("C", bound=ServiceConfig)


class _Shortcut(argparse.Action):
    """An option that stands for `--set <setting>=VALUE`, VALUE taken as written."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: str | Sequence[Any] | None, option_string: str | None = None) -> None:
        text = str(values)
        namespace.overrides = [*namespace.overrides,
                               Override(self.const, text, f"{option_string} {text}", text)]


def service_argparser(name: str, description: str,
                      shortcuts: Mapping[str, tuple[str, str]] | None = None
                      ) -> argparse.ArgumentParser:
    """The options every service takes. `shortcuts`: option -> (setting, help) of the
    options that stand for one `--set` (``{"--port": ("brake.serial.port", ...)}``)."""
    parser = argparse.ArgumentParser(prog=f"aeb {name}", description=description,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", "-c", help="service TOML file (defaults when omitted)")
    parser.add_argument(
        "--connect", action="append", default=None, metavar="ENDPOINT",
        help="Zenoh endpoint to connect to (repeatable), overrides the config's zenoh.connect",
    )
    parser.add_argument("--vehicle", help="vehicle id, overrides the config's vehicle")
    add_log_level(parser)
    parser.add_argument("--check", action="store_true",
                        help="validate the configuration and every file it names as at start, "
                             "then exit (0 valid, 2 invalid) without opening the bus or devices")
    add_set_argument(parser)
    for option, (setting, text) in (shortcuts or {}).items():
        parser.add_argument(option, action=_Shortcut, const=setting, metavar="VALUE",
                            help=f"{text}: the same as --set {setting}=VALUE")
    return parser


def load_service_config(args: argparse.Namespace, config_type: type[C]) -> C:
    """The validated config with the command-line overrides set in it (`--connect`,
    `--vehicle`, `--log-level`, then `--set` and its shortcuts in command-line order), its
    Zenoh settings built into a Zenoh config as the bus will (file, keys, overrides);
    prints and exits 2 when invalid, so that `--check` rejects what a start would."""
    overrides = []
    if args.connect:
        overrides.append(Override("zenoh.connect", "", f"--connect {' '.join(args.connect)}",
                                  list(args.connect)))
    for setting, value, option in (("vehicle", args.vehicle, "--vehicle"),
                                   ("log.level", args.log_level, "--log-level")):
        if value:
            overrides.append(Override(setting, value, f"{option} {value}", value))
    cfg = load_config_or_exit(args.config, config_type, [*overrides, *args.overrides])
    try:
        zenoh_config(cfg.zenoh)
    except BusError as exc:
        print(f"error: {args.config or '<defaults>'}: zenoh: {exc}", file=sys.stderr)
        raise SystemExit(2) from exc
    return cfg


def config_checked(name: str, args: argparse.Namespace) -> int:
    """What `--check` prints once everything a start would validate passed; exit code 0."""
    print(f"{name}: configuration ok ({args.config or 'defaults'})")
    return 0


# How long a clean stop may take after SIGINT/SIGTERM before the process exits anyway.
STOP_GRACE_S = 15.0


class StopEvent(threading.Event):
    """The stop event of `stop_event_on_signals`: its untimed `wait` wakes every
    `_POLL_S`. A signal the kernel delivers to another thread of the process (a Zenoh
    thread) only marks Python's handler as due; it runs when the main thread next runs
    Python code, which an untimed wait on a lock would never let it do."""

    _POLL_S = 0.25

    def wait(self, timeout: float | None = None) -> bool:
        if timeout is not None:
            return super().wait(timeout)
        while not super().wait(self._POLL_S):
            pass
        return True


def stop_event_on_signals(grace_s: float | None = STOP_GRACE_S) -> threading.Event:
    """An event set by SIGINT or SIGTERM (main thread only).

    The first signal also starts a watchdog: a process still alive `grace_s` later exits
    with 128 + the signal's number. A service whose launcher died (PR_SET_PDEATHSIG) has
    nobody left to escalate to SIGKILL, and one that lingers keeps its serial port or
    CAN channel; a stop path that hangs (a blocked join, a library's close) must not do
    that. A stop path that hangs in native code holding the GIL would keep the watchdog's
    thread from running: one second later the kernel ends the process (SIGALRM, its
    default action). `grace_s=None`: no watchdog.
    """
    stop = StopEvent()
    watchdog: list[threading.Timer] = []

    def handler(signum: int, frame: object) -> None:
        stop.set()
        if grace_s is not None and not watchdog:
            timer = threading.Timer(grace_s, os._exit, args=(128 + signum,))
            timer.daemon = True
            timer.start()
            watchdog.append(timer)
            signal.signal(signal.SIGALRM, signal.SIG_DFL)
            signal.setitimer(signal.ITIMER_REAL, grace_s + 1.0)

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop
