"""A SIMULATED stuck subscriber: a process on the vehicle network that subscribes to keys
of the stack and then stops reading them (a monitor paused with Ctrl-Z, a recorder whose
disk hangs, a process frozen by a debugger). docs/security.md says what it can do.

    python -m aeb_radar_camera.tools.faults.stuck --connect tcp/127.0.0.1:7447 \
        [--expr 'aeb/ego/**'] [--block]
    python -m aeb_radar_camera.tools.faults.stuck --connect tcp/127.0.0.1:7447 --load

It prints one line, ``ready``, once subscribed. Without `--block` the caller freezes it
with SIGSTOP; with `--block` its callback blocks on the first sample until SIGTERM (a
subscriber whose callback never returns: Zenoh's reader for its link waits with it).
Either way the kernel's receive buffer of its link fills and then the router's queue to
it: `receive_queue_bytes(pid)` tells a caller how much waits unread. `--load` is the
other half of the fault: camera-sized samples on the camera key (`LOAD_BYTES` at
`LOAD_HZ`, more than a real camera's so that the link fills within seconds) until
SIGTERM, from a process of its own so that the load takes nobody else's interpreter.

Exit code 0 on SIGTERM; 1 when the bus cannot be opened.
"""

import argparse
import os
import sys
import threading
import time
from pathlib import Path

from aeb_radar_camera.common.bus import Bus, BusError
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.keys import CAMERA_JPEG
from aeb_radar_camera.common.service import stop_event_on_signals

_SOCKET = "socket:["
# a receive queue unchanged this long while samples keep coming: the link is full
FILL_STABLE_S = 1.0
# the load: a camera frame is 60 KB at 30 Hz (docs/camera.md)
LOAD_BYTES = 256_000
LOAD_HZ = 50.0


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


def publish_load(bus: Bus, stop: threading.Event, size: int = LOAD_BYTES,
                 hz: float = LOAD_HZ) -> int:
    """Camera-sized samples on the front camera's key until `stop`; returns how many."""
    pub = bus.publisher(CAMERA_JPEG, camera="front")
    payload = bytes(size)
    sent = 0
    while not stop.wait(1 / hz):
        pub.put_bytes(payload)
        sent += 1
    return sent


def wait_filled(pid: int, timeout_s: float, stable_s: float = FILL_STABLE_S,
                poll_s: float = 0.05) -> tuple[int, float]:
    """(bytes, seconds taken) once the receive queues of a frozen process `pid` hold
    something and have not changed for `stable_s`: nothing more gets in, and what the
    router sends it now waits in the router. Raises TimeoutError."""
    t0 = time.monotonic()
    last, since = -1, t0
    while time.monotonic() - t0 < timeout_s:
        now_bytes = receive_queue_bytes(pid)
        if now_bytes != last:
            last, since = now_bytes, time.monotonic()
        elif now_bytes > 0 and time.monotonic() - since >= stable_s:
            return now_bytes, since - t0
        time.sleep(poll_s)
    raise TimeoutError(f"the receive queue of process {pid} did not fill in {timeout_s} s "
                       f"(last {last} bytes)")


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
    parser.add_argument("--load", action="store_true",
                        help="publish the load that fills a stuck subscriber's link instead")
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
            if args.load:
                print("ready", flush=True)
                publish_load(bus, stop)
                return 0
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
