"""`aeb brake`: the brake service (docs/brake.md)."""

import sys
import threading
from collections.abc import Mapping

from aeb_radar_camera.common import systemd
from aeb_radar_camera.common.bus import Bus, BusError
from aeb_radar_camera.common.command_auth import CommandKey, KeyFileError, load_keyring
from aeb_radar_camera.common.config.brake import BrakeConfig
from aeb_radar_camera.common.log import kv, setup_logging
from aeb_radar_camera.common.service import (
    config_checked,
    load_service_config,
    service_argparser,
    stop_event_on_signals,
)
from aeb_radar_camera.common.systemd import Watchdog
from aeb_radar_camera.services.brake.serial_link import simulated_port
from aeb_radar_camera.services.brake.shell import SOURCE, BrakeShell

SHORTCUTS = {"--port": ("brake.serial.port", "actuator serial port")}


def _serve_bus(cfg: BrakeConfig, shell: BrakeShell, stop: threading.Event,
               opened: list[Bus], errors: list[str]) -> None:
    """Blocks until the router is reachable: runs on its own thread so that the timer and
    the actuator link work (and the deadline is enforced) without a bus."""
    try:
        bus = Bus.open(cfg.zenoh, cfg.vehicle, SOURCE)
    except BusError as exc:
        errors.append(str(exc))
        stop.set()
        return
    opened.append(bus)
    if not stop.is_set():
        shell.attach(bus)


def example_key_verdict(cfg: BrakeConfig, keys: Mapping[str, CommandKey]
                        ) -> tuple[str | None, str | None]:
    """(error, warning) about published example keys among `keys`: an error when one is
    meant to move a real actuator without `allow_example_key`, a warning for one that is
    accepted (a simulated actuator, or the opt-in)."""
    examples = [k for k in keys.values() if k.published]
    if not examples:
        return None, None
    names = ", ".join(f"{k.key_id} ({k.path})" for k in examples)
    port = cfg.brake.serial.port
    if simulated_port(port):
        return None, (f"INSECURE EXAMPLE KEY {names}: accepted for the simulated actuator "
                      f"on {port} only")
    if not cfg.brake.allow_example_key:
        return (f"brake.command_keys: {names} is an INSECURE EXAMPLE KEY, published with "
                f"the source (anyone can sign commands with it), and brake.serial.port "
                f"{port} is not a simulated actuator: make a key with `aeb keygen` (or "
                f"`aeb init`), or set brake.allow_example_key = true to accept it on this "
                f"actuator knowingly"), None
    return None, (f"INSECURE EXAMPLE KEY {names} accepted on the REAL actuator {port} "
                  f"(brake.allow_example_key = true): anyone on the network can move "
                  f"this brake")


def main(argv: list[str] | None = None) -> int:
    args = service_argparser("brake", __doc__ or "", SHORTCUTS).parse_args(argv)
    cfg = load_service_config(args, BrakeConfig)
    try:
        keys = load_keyring(cfg.brake.command_keys, cfg.brake.instance)
    except KeyFileError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    error, warning = example_key_verdict(cfg, keys)
    if error is not None:
        print(f"error: {error}", file=sys.stderr)
        return 2
    if args.check:
        if warning is None:
            return config_checked("brake", args)
        # the last line is what `aeb up --check` shows: not "configuration ok"
        print(f"brake: WARNING {warning} ({args.config or 'defaults'})")
        return 0
    log = setup_logging("brake", cfg.log.level.value)
    if warning is not None:
        log.warning(kv("insecure_example_key_accepted", detail=warning))
    stop = stop_event_on_signals()
    # the timer thread waits at most ~1 ms for the GIL instead of the default 5 ms
    sys.setswitchinterval(0.001)
    shell = BrakeShell(cfg, log, Watchdog(), keys)
    shell.start()
    # Ready once the deadline timer and the actuator link run, before the bus: without a
    # router the brake still enforces its fail-safe, which is its service
    systemd.ready("deadline timer and actuator link running; waiting for the bus")
    opened: list[Bus] = []
    errors: list[str] = []
    threading.Thread(target=_serve_bus, args=(cfg, shell, stop, opened, errors),
                     name="brake-bus", daemon=True).start()
    stop.wait()
    shell.stop()
    for bus in opened:
        bus.close()
    if errors:
        print(f"error: {errors[0]}", file=sys.stderr)
        return 2
    log.info(kv("brake_stopped"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
