"""The actuator's serial port (pyserial): a reader thread that opens the port, reopens it
with exponential backoff when it vanishes (USB unplugged, pty closed), and hands what it
reads to a callback; writes come straight from the caller's thread (the command path),
not through a queue, so that a command reaches the line with the least delay."""

import contextlib
import logging
import os
import stat
import threading
from collections.abc import Callable

import serial

from aeb_radar_camera.common.config.brake import SerialSettings
from aeb_radar_camera.common.log import RateLimitedLog, kv
from aeb_radar_camera.common.serial_read import read_available
from aeb_radar_camera.services.brake.protocol import BadLine, LineReader

READ_TIMEOUT_S = 0.05   # how often the reader looks at the stop flag and write failures
WRITE_TIMEOUT_S = 0.02  # a stuck port blocks the command path at most this long
RECONNECT_MIN_S = 0.1   # reopening after the port vanished: 100 ms, doubling ...
RECONNECT_MAX_S = 2.0   # ... up to 2 s


# Linux's pseudo-terminal device majors (Documentation/admin-guide/devices.txt): the
# Unix98 slaves (136-143) and the legacy BSD ones (3)
_PTY_MAJORS = frozenset({3, *range(136, 144)})


def simulated_port(port: str) -> bool:
    """True when `port` is a simulated actuator: it resolves to a pseudo-terminal (the
    simulator's pty, `tools/sim/actuator.py`), or it does not exist yet and lies outside
    /dev (a link the simulator makes in its run folder). Anything else (a USB or UART
    device, a /dev path that is not there yet) is treated as real hardware."""
    path = os.path.realpath(port)
    try:
        st = os.stat(path)
    except OSError:
        return not path.startswith("/dev/")
    return stat.S_ISCHR(st.st_mode) and (path.startswith("/dev/pts/")
                                         or os.major(st.st_rdev) in _PTY_MAJORS)


class SerialLink:
    """One serial port, kept open.

    Callbacks run on the reader thread, never while this object holds its own lock:
    `on_up()` after each successful open, `on_down(reason)` after each loss,
    `on_data(items)` with the lines and discarded runs of `LineReader`.
    """

    def __init__(
        self,
        settings: SerialSettings,
        on_up: Callable[[], None],
        on_down: Callable[[str], None],
        on_data: Callable[[list[bytes | BadLine]], None],
        log: logging.Logger,
    ) -> None:
        self.settings = settings
        self._on_up = on_up
        self._on_down = on_down
        self._on_data = on_data
        self._log = log
        self._rl = RateLimitedLog(log)
        self._port: serial.Serial | None = None
        self._port_lock = threading.Lock()
        self._write_error: str | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="brake-serial", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)

    def write(self, data: bytes) -> bool:
        """Write a whole line now. False when the port is closed or the write failed (the
        reader thread then closes and reopens the port)."""
        with self._port_lock:
            port = self._port
            if port is None or self._write_error is not None:
                return False
            try:
                # straight to the (non-blocking) fd: pyserial's write adds a select and
                # timeout bookkeeping to every line; it only takes over when the kernel
                # buffer is full, and then waits at most WRITE_TIMEOUT_S
                try:
                    n = os.write(port.fd, data)
                except BlockingIOError:
                    n = 0
                if n < len(data):
                    port.write(data[n:])
            except (serial.SerialException, OSError) as exc:
                self._write_error = str(exc)
                return False
            return True

    def _open(self) -> serial.Serial:
        s = self.settings
        return serial.Serial(
            s.port, s.baudrate, timeout=READ_TIMEOUT_S, write_timeout=WRITE_TIMEOUT_S,
            exclusive=s.exclusive,
        )

    def _run(self) -> None:
        s = self.settings
        delay = RECONNECT_MIN_S
        while not self._stop.is_set():
            try:
                port = self._open()
            except (serial.SerialException, OSError, ValueError) as exc:
                self._rl.warning("open", "serial_open_failed", port=s.port, error=exc,
                                 retry_s=delay)
                self._stop.wait(delay)
                delay = min(delay * 2, RECONNECT_MAX_S)
                continue
            delay = RECONNECT_MIN_S
            self._log.info(kv("serial_open", port=s.port))
            with self._port_lock:
                self._port = port
                self._write_error = None
            self._on_up()
            reason = self._read_until_failure(port)
            with self._port_lock:
                self._port = None
            with contextlib.suppress(serial.SerialException, OSError):
                port.close()
            level = logging.INFO if self._stop.is_set() else logging.WARNING
            self._log.log(level, kv("serial_closed", port=s.port, reason=reason))
            self._on_down(reason)
            self._stop.wait(delay)

    def _read_until_failure(self, port: serial.Serial) -> str:
        """Whatever the port holds, in one read per wake-up (common/serial_read.py)."""
        reader = LineReader()
        while not self._stop.is_set():
            if self._write_error is not None:
                return f"write failed: {self._write_error}"
            try:
                data = read_available(port, READ_TIMEOUT_S)
            except (OSError, ValueError, serial.SerialException) as exc:
                return f"read failed: {exc}"
            if data:
                self._on_data(reader.feed(data))
        return "stopped"
