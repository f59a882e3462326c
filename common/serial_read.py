"""Reading everything a pyserial port holds in one call: one `select` with the caller's
timeout, then one `read` (pyserial's `read(in_waiting or 1)` costs a select, an ioctl and
two reads per line). Used by the radar's slcan adapter and the brake's actuator link."""

import os
import select
from typing import Any

READ_SIZE = 4096


class PortGone(OSError):
    """The port said it was readable and had nothing: the other end went away (a USB
    adapter unplugged, a pty closed), as pyserial reports it."""


def read_available(port: Any, timeout: float | None) -> bytes:
    """What `port` (a pyserial port) holds, waiting at most `timeout` seconds (None:
    forever) for the first byte; b"" when nothing came in time. A port without a file
    descriptor (URL handlers such as ``socket://``) reads `in_waiting or 1` bytes with its
    own timeout instead. Raises PortGone, OSError or serial.SerialException when the port
    fails."""
    fd = getattr(port, "fd", None)
    if not isinstance(fd, int):
        return bytes(port.read(port.in_waiting or 1))
    ready, _, _ = select.select([fd], [], [], timeout)
    if not ready:
        return b""
    try:
        data = os.read(fd, READ_SIZE)
    except BlockingIOError:
        return b""
    if not data:
        raise PortGone("serial device reports readiness to read but returned no data "
                       "(disconnected?)")
    return data
