"""A SIMULATED stuck subscriber: a process on the vehicle network that subscribes to keys
of the stack and then stops reading them (a monitor paused with Ctrl-Z, a recorder whose
disk hangs, a process frozen by a debugger). docs/security.md says what it can do.

    python -m aeb_radar_camera.tools.faults.stuck --connect tcp/127.0.0.1:7447 \
        [--expr 'aeb/ego/**'] [--block]
    python -m aeb_radar_camera.tools.faults.stuck --connect tcp/127.0.0.1:7447 --load

It prints one line, ``ready``, once the first sample has arrived (the router then routes
the keys to it: a process frozen right after declaring its subscriber may not have sent
the declaration yet). Without `--block` the caller freezes it
with SIGSTOP; with `--block` its callback blocks on the first sample until SIGTERM (a
subscriber whose callback never returns: Zenoh's reader for its link waits with it).
Either way the kernel's receive buffer of its link fills and then the router's queue to
it: `receive_queue_bytes(pid)` tells a caller how much waits unread, and
`send_queue_bytes_to(router, pid)` how much waits in the router's kernel for it. `--load` is the
other half of the fault: camera-sized samples on the key of a camera named `load`, which
no service reads (`LOAD_BYTES` at `LOAD_HZ`, more than a real camera's so that the link
fills within seconds whatever else runs) until SIGTERM, from a process of its own so that
the load takes nobody else's interpreter.

Exit code 0 on SIGTERM; 1 when the bus cannot be opened or no sample arrives within
`FIRST_SAMPLE_TIMEOUT_S`.
"""

import argparse
import ctypes
import fcntl
import os
import socket
import struct
import sys
import termios
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from aeb_radar_camera.common.bus import Bus, BusError
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.keys import CAMERA_JPEG
from aeb_radar_camera.common.service import stop_event_on_signals

_SOCKET = "socket:["
_SYS_PIDFD_GETFD = 438
_libc = ctypes.CDLL(None, use_errno=True)
# a receive queue unchanged this long while samples keep coming: the link is full
FILL_STABLE_S = 1.0
# the load: a camera frame is 60 KB at 30 Hz (docs/camera.md)
LOAD_CAMERA = "load"
LOAD_BYTES = 256_000
LOAD_HZ = 50.0
FIRST_SAMPLE_TIMEOUT_S = 60.0


def _pidfd_getfd(pidfd: int, fd: int) -> int:
    """A duplicate of another process's descriptor (pidfd_getfd(2), Linux 5.6, the same
    syscall number on every architecture; needs the right to ptrace it). Raises OSError."""
    dup = int(_libc.syscall(_SYS_PIDFD_GETFD, pidfd, fd, 0))
    if dup < 0:
        err = ctypes.get_errno()
        raise OSError(err, os.strerror(err))
    return dup


def _sockets(pid: int) -> Iterator[socket.socket]:
    """Duplicates of the sockets process `pid` holds (pidfd_getfd), each closed once the
    caller moves on; none when it is gone. Raises OSError when the process's descriptors
    may not be borrowed (another user's process without root)."""
    try:
        pidfd = os.pidfd_open(pid)
    except ProcessLookupError:
        return
    try:
        try:
            names = list(Path(f"/proc/{pid}/fd").iterdir())
        except OSError:
            return
        for name in names:
            try:
                if not os.readlink(name).startswith(_SOCKET):
                    continue
                dup = _pidfd_getfd(pidfd, int(name.name))
            except (OSError, ValueError):
                continue    # closed meanwhile
            with socket.socket(fileno=dup) as sock:
                yield sock
    finally:
        os.close(pidfd)


def _queued(sock: socket.socket, request: int) -> int:
    try:
        return int(struct.unpack("i", fcntl.ioctl(sock.fileno(), request, b"\0" * 4))[0])
    except OSError:
        return 0            # a listening socket has no queues


def _name(sock: socket.socket, peer: bool) -> object:
    """The socket's own or its peer's address (None for other than TCP/IP)."""
    if sock.family not in (socket.AF_INET, socket.AF_INET6):
        return None
    try:
        return sock.getpeername() if peer else sock.getsockname()
    except OSError:
        return None


def receive_queue_bytes(pid: int) -> int:
    """Bytes received by the kernel that process `pid` has not read, over its sockets
    (FIONREAD on each: microseconds, where /proc/net/tcp walks the host's whole
    connection table, some 13 ms on the test VM). Raises OSError (see `_sockets`)."""
    return sum(_queued(s, termios.FIONREAD) for s in _sockets(pid))


def send_queue_bytes_to(sender: int, receiver: int) -> int:
    """Bytes process `sender` has written to its TCP connections with process
    `receiver` that the receiver's kernel has not taken yet (TIOCOUTQ). Raises OSError
    (see `_sockets`)."""
    ends = {_name(s, peer=False) for s in _sockets(receiver)} - {None}
    return sum(_queued(s, termios.TIOCOUTQ) for s in _sockets(sender)
               if _name(s, peer=True) in ends)


def publish_load(bus: Bus, stop: threading.Event, size: int = LOAD_BYTES,
                 hz: float = LOAD_HZ) -> int:
    """Camera-sized samples on camera `load`'s key until `stop`; returns how many."""
    pub = bus.publisher(CAMERA_JPEG, camera=LOAD_CAMERA)
    payload = bytes(size)
    sent = 0
    while not stop.wait(1 / hz):
        pub.put_bytes(payload)
        sent += 1
    return sent


def wait_filled(pid: int, timeout_s: float, router: int | None = None,
                stable_s: float = FILL_STABLE_S, poll_s: float = 0.05) -> tuple[int, float]:
    """(bytes, seconds taken) once the receive queues of a frozen process `pid` (and,
    given the `router`'s pid, the router's send queue to it) hold something and have not
    changed for `stable_s`: nothing more gets in, and what the router sends it now waits
    in the router's own queue. Raises TimeoutError."""
    t0 = time.monotonic()
    last, since = (-1, -1), t0
    while time.monotonic() - t0 < timeout_s:
        now = (receive_queue_bytes(pid),
               send_queue_bytes_to(router, pid) if router is not None else 0)
        if now != last:
            last, since = now, time.monotonic()
        elif now[0] > 0 and time.monotonic() - since >= stable_s:
            return sum(now), since - t0
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
    parser.add_argument("--load-bytes", type=int, default=LOAD_BYTES)
    parser.add_argument("--load-hz", type=float, default=LOAD_HZ)
    args = parser.parse_args(argv)
    stop = stop_event_on_signals()
    settings = ZenohSettings(mode=ZenohMode.CLIENT, connect=tuple(args.connect),
                             config_file=args.zenoh_config)
    expr = args.expr or f"aeb/{args.vehicle}/**"
    first = threading.Event()

    def on_sample(payload: bytes, key: str, encoding: str, t_ns: int) -> None:
        first.set()
        if args.block:
            stop.wait()     # Zenoh's reader of this link waits here: nothing more is read

    try:
        with Bus.open(settings, args.vehicle, "stuck") as bus:
            if args.load:
                print("ready", flush=True)
                publish_load(bus, stop, args.load_bytes, args.load_hz)
                return 0
            sub = bus.subscribe_expr(expr, on_sample)
            deadline = time.monotonic() + FIRST_SAMPLE_TIMEOUT_S
            while not first.wait(0.1):
                if stop.is_set():
                    return 0
                if time.monotonic() > deadline:
                    print(f"error: no sample on {expr} in {FIRST_SAMPLE_TIMEOUT_S:g} s",
                          file=sys.stderr)
                    return 1
            print("ready", flush=True)
            stop.wait()
            sub.undeclare()
    except BusError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
