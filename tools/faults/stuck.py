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
other half of the fault: camera-sized samples on the key of a camera named `load`, which
no service reads (`LOAD_BYTES` at `LOAD_HZ`, more than a real camera's so that the link
fills within seconds whatever else runs) until SIGTERM, from a process of its own so that
the load takes nobody else's interpreter.

Exit code 0 on SIGTERM; 1 when the bus cannot be opened.
"""

import argparse
import ctypes
import fcntl
import os
import struct
import sys
import termios
import threading
import time
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


def _pidfd_getfd(pidfd: int, fd: int) -> int:
    """A duplicate of another process's descriptor (pidfd_getfd(2), Linux 5.6, the same
    syscall number on every architecture; needs the right to ptrace it). Raises OSError."""
    dup = int(_libc.syscall(_SYS_PIDFD_GETFD, pidfd, fd, 0))
    if dup < 0:
        err = ctypes.get_errno()
        raise OSError(err, os.strerror(err))
    return dup


def receive_queue_bytes(pid: int) -> int:
    """Bytes received by the kernel that process `pid` has not read, summed over its
    sockets (0 when it is gone). Each socket is borrowed with pidfd_getfd and asked with
    FIONREAD: microseconds, where /proc/net/tcp walks the host's whole connection table
    (some 13 ms on the test VM, costly at a polling rate). Raises OSError when the
    process's descriptors may not be borrowed (another user's process without root)."""
    try:
        pidfd = os.pidfd_open(pid)
    except ProcessLookupError:
        return 0
    total = 0
    try:
        try:
            names = list(Path(f"/proc/{pid}/fd").iterdir())
        except OSError:
            return 0
        for name in names:
            try:
                if not os.readlink(name).startswith(_SOCKET):
                    continue
                dup = _pidfd_getfd(pidfd, int(name.name))
            except (OSError, ValueError):
                continue    # closed meanwhile
            try:
                total += struct.unpack("i", fcntl.ioctl(dup, termios.FIONREAD, b"\0" * 4))[0]
            except OSError:
                pass        # a listening socket has no receive queue
            finally:
                os.close(dup)
    finally:
        os.close(pidfd)
    return total


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
    parser.add_argument("--load-bytes", type=int, default=LOAD_BYTES)
    parser.add_argument("--load-hz", type=float, default=LOAD_HZ)
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
                publish_load(bus, stop, args.load_bytes, args.load_hz)
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
