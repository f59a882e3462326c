"""A Zenoh router run from Python (zenoh's own router mode): `aeb router`.

An address or port that is not available yet is waited out, not a configuration error:
a port still held by a process that is going away, or a board's vehicle-network address
not up yet (cable, DHCP, NetworkManager later than us). The router logs what it waits
for (`listen_address_unavailable`, then every `STILL_WAITING_LOG_S`), retries with
backoff, and serves once every endpoint listens. Exit code 2 is left to what a restart
cannot fix: a malformed endpoint or Zenoh config.
"""

import argparse
import errno
import json
import logging
import re
import socket
import sys
import threading
import time

import zenoh

from aeb_radar_camera.common import systemd
from aeb_radar_camera.common.bus import BusError, open_session, zenoh_config
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.config.realtime import RealtimeSettings
from aeb_radar_camera.common.log import add_log_level, kv, setup_logging
from aeb_radar_camera.common.realtime import ThreadRealtime
from aeb_radar_camera.common.service import stop_event_on_signals

# What a bind fails with when the address or port is not available *yet*.
WAITABLE = {errno.EADDRINUSE: "address already in use (by another process, or one going "
                              "away)",
            errno.EADDRNOTAVAIL: "address not on this machine (yet: interface down, no "
                                 "cable, no DHCP lease)"}
RETRY_FIRST_S = 0.5
RETRY_MAX_S = 5.0
STILL_WAITING_LOG_S = 30.0

# Zenoh's own words for a listener it could not bind: "... listener bound to
# tcp/192.168.10.1:7447: [...: Cannot assign requested address (os error 99) at ...]"
_BIND_FAILED = re.compile(r"listener bound to (?P<endpoint>\S+?):\s.*?\(os error (?P<errno>\d+)\)")
_HOST_PORT = re.compile(r"^(?P<proto>[a-z]+)/(?:\[(?P<v6>[^\]]+)\]|(?P<host>[^:/\[\]]+)):"
                        r"(?P<port>\d+)")


def router_settings(listen: list[str], connect: list[str], config_file: str = "") -> ZenohSettings:
    return ZenohSettings(
        mode=ZenohMode.ROUTER, listen=tuple(listen), connect=tuple(connect),
        config_file=config_file,
    )


def bind_failure(message: str) -> tuple[str, int] | None:
    """(endpoint, errno) when zenoh's error says a listener could not bind for a reason
    to wait out (WAITABLE); None for anything else."""
    m = _BIND_FAILED.search(message)
    if m is None or int(m.group("errno")) not in WAITABLE:
        return None
    return m.group("endpoint"), int(m.group("errno"))


def probe(endpoint: str) -> str:
    """Whether a TCP or UDP endpoint could be bound on this machine now: "free now", why
    not ("not available now: ..."), or "not probed" (another transport, a name that does
    not resolve). Binds and closes at once, as zenoh would bind (SO_REUSEADDR)."""
    m = _HOST_PORT.match(endpoint.split("?")[0].split("#")[0])
    if m is None:
        return "not probed"
    kind = socket.SOCK_DGRAM if m.group("proto") in ("udp", "quic") else socket.SOCK_STREAM
    host = m.group("v6") or m.group("host")
    try:
        infos = socket.getaddrinfo(host, int(m.group("port")), type=kind)
    except (OSError, UnicodeError):
        return "not probed"
    family, _, _, _, address = infos[0]
    with socket.socket(family, kind) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(address)
        except OSError as exc:
            return f"not available now: {exc.strerror}" if exc.errno in WAITABLE else (
                f"cannot be bound: {exc.strerror}")
    return "free now"


def open_when_available(settings: ZenohSettings, stop: threading.Event,
                        log: logging.Logger, feed: systemd.Watchdog) -> zenoh.Session | None:
    """The router's session once every endpoint could be bound (None: `stop` was set
    first). Raises BusError for a failure a wait cannot fix."""
    delay = RETRY_FIRST_S
    waiting_since: float | None = None
    next_log = 0.0
    while True:
        try:
            session = open_session(settings)
        except BusError as exc:
            failure = bind_failure(str(exc))
            if failure is None:
                raise
            endpoint, code = failure
            now = time.monotonic()
            first = waiting_since is None
            if waiting_since is None:
                waiting_since = now
            if now >= next_log:
                event = "listen_address_unavailable" if first else \
                    "still_waiting_for_listen_address"
                log.warning(kv(event, endpoint=endpoint, reason=WAITABLE[code],
                               waited_s=round(now - waiting_since, 1), retry_max_s=RETRY_MAX_S))
                systemd.status(f"waiting for {endpoint}: {WAITABLE[code]}")
                next_log = now + STILL_WAITING_LOG_S
            if feed.wait(stop, delay):
                return None
            delay = min(RETRY_MAX_S, delay * 2)
            continue
        if waiting_since is not None:
            log.info(kv("listen_address_available",
                        waited_s=round(time.monotonic() - waiting_since, 1)))
        return session


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="aeb router", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
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
                        help="validate the settings and the Zenoh config, say whether each "
                             "listen address is free now, then exit (0 or 2)")
    args = parser.parse_args(argv)
    log = setup_logging("router", args.log_level)
    listen = args.listen or ([] if args.config_file else ["tcp/127.0.0.1:7447"])
    stop = stop_event_on_signals()
    watchdog = systemd.Watchdog()
    try:
        settings = router_settings(listen, args.connect, args.config_file)
        # What the router really listens on: the config file's endpoints when none are given.
        listening = [str(e) for e in
                     json.loads(zenoh_config(settings).get_json("listen/endpoints")) or []]
        if args.check:
            # The configuration is checked; an address is only looked at: one not up now
            # is waited for at start, not an error.
            said = "; ".join(f"{e} {probe(e)}" for e in listening)
            print(f"router: configuration ok ({args.config_file or 'no config file'}); "
                  f"listen {said or '(none)'}")
            return 0
        # Every thread of a router is Zenoh's, and each inherits the policy of the thread
        # that created it: real-time before the session exists, they all are.
        ThreadRealtime(RealtimeSettings(priority=args.realtime_priority), log,
                       "router").ensure()
        session = open_when_available(settings, stop, log, watchdog)
    except (BusError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if session is None:
        log.info(kv("router_stopped", listening=False))
        return 0
    with session:
        log.info(kv("router_ready", listen=",".join(listening), zid=str(session.zid())))
        systemd.ready(f"listening on {','.join(listening)}")
        while not watchdog.wait(stop, 3600.0):
            pass
    log.info(kv("router_stopped"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
