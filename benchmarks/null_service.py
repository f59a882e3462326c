"""The cost floor of a service: a Python process with a Zenoh session that receives every
key of the stack (the simulator's too) and does nothing with it.
`python -m benchmarks.null_service --connect EP`.

Ready when its liveliness token `health/bench/null` is up; stops on SIGTERM.
"""

import argparse
import sys

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.tools.keys import MESSAGE_KEYS


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.null_service")
    parser.add_argument("--connect", required=True)
    parser.add_argument("--vehicle", default="ego")
    args = parser.parse_args(argv)
    stop = stop_event_on_signals()
    received = [0]

    def on_raw(payload: bytes, key: str, rx_mono_ns: int) -> None:
        received[0] += 1

    settings = ZenohSettings(mode=ZenohMode.CLIENT, connect=(args.connect,))
    with Bus.open(settings, args.vehicle, "bench/null") as bus:
        subs = [bus.subscribe_raw(spec, on_raw) for spec in MESSAGE_KEYS]
        token = bus.declare_health("bench", "null")
        stop.wait()
        token.undeclare()
        for sub in subs:
            sub.undeclare()
    print(f"received {received[0]} samples", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
