"""A SIMULATED stuck subscriber: a process on the vehicle network that subscribes to keys
of the stack and then stops reading them (a monitor paused with Ctrl-Z, a recorder whose
disk hangs, a process frozen by a debugger). docs/security.md says what it can do.

    python -m aeb_radar_camera.tools.faults.stuck --connect tcp/127.0.0.1:7447 \
        [--expr 'aeb/ego/**'] [--block]

It prints one line, ``ready``, once subscribed. Without `--block` the caller freezes it
with SIGSTOP; with `--block` its callback blocks on the first sample until SIGTERM (a
subscriber whose callback never returns: Zenoh's reader for its link waits with it).
Either way the kernel's receive buffer of its link fills and then the router's queue to
it: `receive_queue_bytes(pid)` tells a caller how much waits unread.

Exit code 0 on SIGTERM; 1 when the bus cannot be opened.
"""

import argparse
import os
import sys
import threading
from pathlib import Path

from aeb_radar_camera.common.bus import Bus, BusError
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.service import stop_event_on_signals

_SOCKET = "socket:["


def socket_inodes(pid: int) -> set[int]:
    """The inodes of the sockets process `pid` holds open (empty when it is gone)."""
    inodes = set()
    fd_dir = Path(f"/proc/{pid}/fd")
    try:
        names = list(fd_dir.iterdir())
    except OSError:
        return set()
    for fd in names:
        try:
            target = os.readlink(fd)
        except OSError:
            continue    # closed meanwhile
        if target.startswith(_SOCKET):
            inodes.add(int(target[len(_SOCKET):-1]))
    return inodes


def parse_rx_queues(table: str, inodes: set[int]) -> int:
    """The sum of `rx_queue` over the rows of a /proc/net/tcp table whose inode is in
    `inodes` (bytes received by the kernel that the process has not read). Rows that do
    not parse are skipped."""
    total = 0
    for line in table.splitlines()[1:]:
        fields = line.split()
        if len(fields) < 10:
            continue
        try:
            inode = int(fields[9])
            rx = int(fields[4].split(":")[1], 16)
        except (ValueError, IndexError):
            continue
        if inode in inodes:
            total += rx
    return total


def receive_queue_bytes(pid: int) -> int:
    """Bytes waiting unread in the TCP receive queues of process `pid` (IPv4 and IPv6)."""
    inodes = socket_inodes(pid)
    total = 0
    for name in ("tcp", "tcp6"):
        try:
            table = Path(f"/proc/net/{name}").read_text(encoding="ascii")
        except OSError:
            continue
        total += parse_rx_queues(table, inodes)
    return total


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m aeb_radar_camera.tools.faults.stuck", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--connect", action="append", default=[])
    parser.add_argument("--zenoh-config", default="", help="Zenoh JSON5 (e.g. a TLS client)")
    parser.add_argument("--vehicle", default="ego")
    parser.add_argument("--expr", default="", help="key expression (default: aeb/<vehicle>/**)")
    parser.add_argument("--block", action="store_true",
                        help="block in the callback on the first sample until SIGTERM")
    args = parser.parse_args(argv)
    stop = stop_event_on_signals()
    settings = ZenohSettings(mode=ZenohMode.CLIENT, connect=tuple(args.connect),
                             config_file=args.zenoh_config)
    expr = args.expr or f"aeb/{args.vehicle}/**"
    blocked = threading.Event()

    def on_sample(payload: bytes, key: str, encoding: str, t_ns: int) -> None:
        if args.block:
            blocked.set()
            stop.wait()     # Zenoh's reader of this link waits here: nothing more is read

    try:
        with Bus.open(settings, args.vehicle, "stuck") as bus:
            sub = bus.subscribe_expr(expr, on_sample)
            print("ready", flush=True)
            stop.wait()
            sub.undeclare()
    except BusError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
