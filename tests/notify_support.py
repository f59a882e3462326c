"""The receiving end of sd_notify for tests: what systemd's manager does with
$NOTIFY_SOCKET, including the sender's credentials (NotifyAccess=main compares its pid)."""

import os
import socket
import struct
from pathlib import Path
from typing import Any


class NotifyListener:
    """An AF_UNIX datagram socket at `address` (a path, or ``@name``); `env` points a
    child process at it."""

    def __init__(self, address: str | Path) -> None:
        self.address = str(address)
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_PASSCRED, 1)
        bind = "\0" + self.address[1:] if self.address.startswith("@") else self.address
        self.sock.bind(bind)
        self.env = {"NOTIFY_SOCKET": self.address}

    def __enter__(self) -> "NotifyListener":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.sock.close()
        if not self.address.startswith("@"):
            os.unlink(self.address)

    def receive(self, timeout_s: float) -> tuple[int, str]:
        """(sender pid, text) of the next datagram. Raises socket.timeout."""
        self.sock.settimeout(timeout_s)
        data, ancillary, _, _ = self.sock.recvmsg(4096, socket.CMSG_SPACE(12))
        pid = -1
        for level, kind, payload in ancillary:
            if level == socket.SOL_SOCKET and kind == socket.SCM_CREDENTIALS:
                pid = struct.unpack("iII", payload[:12])[0]
        return pid, data.decode()

    def collect(self, timeout_s: float, until: str, count: int = 1) -> list[tuple[int, str]]:
        """Every datagram until `count` of them contain `until`, or `timeout_s` passes
        (then socket.timeout)."""
        import time

        got: list[tuple[int, str]] = []
        deadline = time.monotonic() + timeout_s
        while sum(until in text for _, text in got) < count:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"{until!r} x{count} not received; got {got}")
            got.append(self.receive(left))
        return got
