"""A stand-in fusion instance for the brake tests: publishes one BrakeCommand every
`--period-ms` (BRAKE at `--level` when > 0, else NONE), signed with `--key`, until
SIGTERM. The tests SIGKILL or SIGSTOP it to make the command stream stop.

    python -m tests.brake.publisher --connect tcp/127.0.0.1:7447 --level 60
"""

import argparse
import logging
import sys
import time

import msgspec

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.command_auth import CommandSigner, load_key
from aeb_radar_camera.common.config.realtime import RealtimeSettings
from aeb_radar_camera.common.keys import FUSION_BRAKE_CMD
from aeb_radar_camera.common.realtime import apply_process
from aeb_radar_camera.common.service import stop_event_on_signals
from tests.brake.helpers import command
from tests.support import client_settings


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--connect", required=True)
    parser.add_argument("--instance", default="primary")
    parser.add_argument("--vehicle", default="ego")
    parser.add_argument("--period-ms", type=float, default=20.0)
    parser.add_argument("--level", type=float, default=0.0)
    parser.add_argument("--key", help="key file to sign with (default: unsigned)")
    parser.add_argument("--zenoh-config", default="", help="Zenoh JSON5 (a TLS client)")
    parser.add_argument("--realtime-priority", type=int, default=0,
                        help="SCHED_FIFO for its threads, as a deployed fusion's")
    args = parser.parse_args(argv)
    stop = stop_event_on_signals()
    signer = CommandSigner(load_key(args.key)) if args.key else None
    period = args.period_ms / 1000
    settings = msgspec.structs.replace(client_settings(args.connect),
                                       config_file=args.zenoh_config)
    with Bus.open(settings, args.vehicle, f"fusion/{args.instance}") as bus:
        pub = bus.publisher(FUSION_BRAKE_CMD, instance=args.instance)
        apply_process(RealtimeSettings(priority=args.realtime_priority),
                      logging.getLogger("publisher"))
        seq = 0
        next_t = time.monotonic()
        while not stop.is_set():
            cmd = command(seq, args.level, instance=args.instance)
            if signer is None:
                pub.put(cmd)
            else:
                pub.put_bytes(signer.sign(cmd))
            seq += 1
            next_t += period
            now = time.monotonic()
            if next_t < now:          # resumed after SIGSTOP: no burst of stale periods
                next_t = now + period
            stop.wait(next_t - now)
    return 0


if __name__ == "__main__":
    sys.exit(main())
