"""A Zenoh router run from Python (zenoh's own router mode): `aeb router`."""

import argparse
import json
import sys

from common import systemd
from common.bus import BusError, open_session, zenoh_config
from common.config.base import ZenohMode, ZenohSettings
from common.config.realtime import RealtimeSettings
from common.log import add_log_level, kv, setup_logging
from common.realtime import ThreadRealtime
from common.service import stop_event_on_signals


def router_settings(listen: list[str], connect: list[str], config_file: str = "") -> ZenohSettings:
    return ZenohSettings(
        mode=ZenohMode.ROUTER, listen=tuple(listen), connect=tuple(connect),
        config_file=config_file,
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="aeb router", description=__doc__)
    parser.add_argument("--listen", action="append", default=None,
                        help="endpoint to listen on (repeatable), default tcp/127.0.0.1:7447")
    parser.add_argument("--connect", action="append", default=[],
                        help="another router to connect to (repeatable)")
    parser.add_argument("--config-file", default="", help="zenoh JSON5 router config")
    parser.add_argument("--realtime-priority", type=int, default=0, choices=range(100),
                        metavar="0..99",
                        help="SCHED_FIFO priority for the router's Zenoh I/O threads (0: "
                             "normal scheduling; needs CAP_SYS_NICE; see docs/deploy.md)")
    add_log_level(parser, "INFO")
    parser.add_argument("--check", action="store_true",
                        help="validate the settings and the Zenoh config, then exit (0 or 2)")
    args = parser.parse_args(argv)
    log = setup_logging("router", args.log_level)
    listen = args.listen or ([] if args.config_file else ["tcp/127.0.0.1:7447"])
    stop = stop_event_on_signals()
    try:
        settings = router_settings(listen, args.connect, args.config_file)
        # What the router really listens on: the config file's endpoints when none are given.
        listening = json.loads(zenoh_config(settings).get_json("listen/endpoints"))
        if args.check:
            print(f"router: configuration ok ({args.config_file or 'no config file'}, "
                  f"listen {','.join(map(str, listening or []))})")
            return 0
        # Every thread of a router is Zenoh's, and each inherits the policy of the thread
        # that created it: real-time before the session exists, they all are.
        ThreadRealtime(RealtimeSettings(priority=args.realtime_priority), log,
                       "router").ensure()
        session = open_session(settings)
    except (BusError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    with session:
        log.info(kv("router_ready", listen=",".join(map(str, listening or [])),
                    zid=str(session.zid())))
        systemd.ready(f"listening on {','.join(map(str, listening or []))}")
        watchdog = systemd.Watchdog()
        while not watchdog.wait(stop, 3600.0):
            pass
    log.info(kv("router_stopped"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
