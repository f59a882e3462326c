"""python-can's `slcan` interface, reading every byte the adapter has at once.

python-can 4.6's slcanBus reads the serial port one byte per call and waits for data by
polling: a cycle's last frames queue behind the bytes of the ones before, and an idle bus
keeps waking the reader. With it the radar service would not stay within its CPU budget
(docs/performance.md). `BulkSlcanBus` keeps python-can's slcan commands, parsing and
Message objects and replaces only the read: one `select` with the caller's whole
timeout, then one `read` of everything available, split into lines. Every service that
reads CAN opens it for `interface = "slcan"` (common/can_port.py).

Lines that are not valid (bad hex, a length that disagrees with the DLC, bytes that are
not ASCII, a run longer than any slcan line) are dropped, counted in `line_errors` by
reason and logged with a rate limit; they never raise out of `recv`. A port that fails
(adapter unplugged, pty closed) raises can.CanOperationError, as python-can does.

Ports without a file descriptor (URL handlers such as ``socket://``, Windows) use
pyserial's `read(in_waiting)` with the port's own timeout instead of `select`.
"""

import logging
import re
import time
from collections import deque
from typing import Any

import can
from can.interfaces.slcan import slcanBus

from aeb_radar_camera.common.counters import ReasonCounter
from aeb_radar_camera.common.log import RateLimitedLog
from aeb_radar_camera.common.serial_read import PortGone, read_available

# 'D' + 8-digit ID + DLC + 64 data bytes (CAN FD), the longest line an adapter sends
MAX_LINE = 1 + 8 + 1 + 128
_LINE = re.compile(rb"[^\r\x07]*[\r\x07]")
# python-can's own frame letters, and adapter replies that are not frames (ignored)
_FRAME = frozenset("tTxrRdDbB")
_REPLY = frozenset("zZVvNF")


def _kind(line: str) -> str:
    """'frame' (python-can parses it), 'reply' (an adapter's answer, or empty) or
    'unknown'."""
    if line in ("\r", "\x07"):
        return "reply"
    if line[0] in _FRAME:
        return "frame"
    return "reply" if line[0] in _REPLY else "unknown"


class BulkSlcanBus(slcanBus):
    """slcanBus with a bulk, select-based read. Same constructor arguments, plus
    `log_name`: the logger of the dropped-line warnings (``<service>.slcan``)."""

    def __init__(self, channel: Any, log_name: str = "slcan", **kwargs: Any) -> None:
        self._lines: deque[str] = deque()
        self._last_line: str | None = None
        self.line_errors = ReasonCounter()
        self._rl = RateLimitedLog(logging.getLogger(log_name))
        super().__init__(channel, **kwargs)

    # -- reading ----------------------------------------------------------------------

    def _read(self, timeout: float | None) -> str | None:
        """The next line with its terminator, or None when `timeout` passes first."""
        if self._lines:
            self._last_line = self._lines.popleft()
            return self._last_line
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            chunk = self._read_available(left)
            if chunk:
                self._split(chunk)
                if self._lines:
                    self._last_line = self._lines.popleft()
                    return self._last_line
            if deadline is not None and time.monotonic() >= deadline:
                return None

    def _read_available(self, timeout: float | None) -> bytes:
        """What the port has, waiting at most `timeout` for the first byte. Raises
        can.CanOperationError when the port fails or vanished."""
        try:
            return read_available(self.serialPortOrig, timeout)
        except PortGone as exc:
            raise can.CanOperationError(str(exc)) from exc
        except (OSError, ValueError) as exc:   # EIO: unplugged; SerialException; a closed fd
            raise can.CanOperationError(f"could not read from serial device: {exc}") from exc

    def _split(self, chunk: bytes) -> None:
        buf = self._buffer
        buf += chunk
        end = 0
        for m in _LINE.finditer(buf):
            raw = m.group()
            end = m.end()
            if len(raw) > MAX_LINE + 1:
                self._bad("too_long", raw)
                continue
            try:
                self._lines.append(raw.decode("ascii"))
            except UnicodeDecodeError:
                self._bad("not_ascii", raw)
        del buf[:end]
        if len(buf) > MAX_LINE:    # no terminator in sight: noise, not a line
            self._bad("too_long", bytes(buf))
            buf.clear()

    def _bad(self, reason: str, raw: bytes) -> None:
        self.line_errors.add(reason)
        self._rl.warning(f"slcan:{reason}", "slcan_line_dropped", reason=reason,
                         line=raw[:40].hex())

    # -- parsing (python-can's, guarded) ------------------------------------------------

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        self._last_line = None
        try:
            msg, filtered = super()._recv_internal(timeout)
        except (ValueError, IndexError, KeyError):
            self._bad("malformed", (self._last_line or "").encode())
            return None, False
        line = self._last_line
        if msg is None:
            if line is not None and _kind(line) != "reply":
                self._bad("unknown", line.encode())
            return None, filtered
        if not msg.is_remote_frame and len(msg.data) != msg.dlc:
            self._bad("length", (line or "").encode())
            return None, False
        return msg, filtered

    def flush(self) -> None:
        self._lines.clear()
        super().flush()
