"""Where a service's CAN frames come from: any python-can bus, or a recorded log replayed
through python-can's readers (candump .log, .asc, .blf, .trc, ...), paced in real time or
as fast as possible, optionally looping. Shared by every service that reads CAN (the
radar, the vehicle gateway); `service` names the config table in errors and the logger.
"""

import io
import logging
import math
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Protocol

import can
from can.io.canutils import CanutilsLogReader

from aeb_radar_camera.common.config.can import REPLAY, CanSettings, Pace, ReplaySettings
from aeb_radar_camera.common.counters import ReasonCounter
from aeb_radar_camera.common.log import RateLimitedLog
from aeb_radar_camera.common.slcan_bulk import BulkSlcanBus

SLCAN = "slcan"
_LOOP_GAP_S = 0.075   # time inserted between the end of a log and its restart (one radar cycle)
# what python-can's log readers raise on a malformed line or record
# A recorded stamp further than this from the previous frame's (or before it) is not the
# log's time line: a radar transmits every 75 ms, a log with a gap of minutes was cut
_MAX_STAMP_GAP_S = 10.0
_BAD_RECORD = (ValueError, IndexError, TypeError, OverflowError, UnicodeDecodeError)


class CanPort(Protocol):
    """What a service needs from a bus: python-can's BusABC satisfies it."""

    def recv(self, timeout: float | None = None) -> can.Message | None: ...

    def send(self, msg: can.Message, timeout: float | None = None) -> None: ...

    def shutdown(self) -> None: ...


class ConfigurationError(ValueError):
    """A CAN setting that can never work (unknown interface, missing replay file)."""


def check_settings(c: CanSettings, r: ReplaySettings, service: str) -> None:
    """Fail fast on settings no retry can fix, naming them as `[<service>.can]` /
    `[<service>.replay]`. Raises ConfigurationError."""
    if c.interface == REPLAY:
        try:
            readable = Path(r.file).is_file()
        except OSError as exc:    # e.g. a name longer than the file system allows
            raise ConfigurationError(
                f"{service}.replay.file {r.file!r}: {exc.strerror}") from exc
        if not readable:
            raise ConfigurationError(f"{service}.replay.file {r.file!r} is not a readable file")
    elif c.interface not in can.interfaces.VALID_INTERFACES:
        raise ConfigurationError(
            f"{service}.can.interface {c.interface!r} is not a python-can interface "
            f"(one of: {', '.join(sorted(can.interfaces.VALID_INTERFACES))}, or 'replay')"
        )


def open_port(c: CanSettings, r: ReplaySettings, service: str) -> CanPort:
    """Open the configured bus for `service` (its loggers: ``<service>.replay``,
    ``<service>.slcan``). Raises can.CanError, OSError (pyserial's SerialException
    included) or ValueError when the device is not there or refuses the settings, as
    python-can does: the shell retries with backoff.

    `slcan` opens common.slcan_bulk.BulkSlcanBus (python-can's slcan with a bulk read)."""
    if c.interface == REPLAY:
        return ReplayPort(r.file, pace=r.pace, loop=r.loop, log_name=f"{service}.replay")
    kwargs = dict(c.options)
    if c.bitrate:
        kwargs.setdefault("bitrate", c.bitrate)
    if c.interface == SLCAN:
        # python-can's configuration sources still apply, as in can.Bus
        config = can.util.load_config(
            config={"interface": SLCAN, "channel": c.channel, **kwargs})
        config.pop("interface", None)
        return BulkSlcanBus(config.pop("channel", c.channel), log_name=f"{service}.slcan",
                            **config)
    bus: CanPort = can.Bus(interface=c.interface, channel=c.channel, **kwargs)
    return bus


def describe(c: CanSettings, r: ReplaySettings) -> tuple[str, str]:
    """(interface, channel) as a service's status reports them."""
    if c.interface == REPLAY:
        return REPLAY, r.file
    return c.interface, c.channel


class ReplayPort:
    """A recorded log as a receive-only bus.

    Frames keep their recorded timestamps (plus an offset per loop, so that time never
    goes backwards); with `Pace.REALTIME` each frame is returned at its recorded spacing
    from the first one. `ended` turns true when a non-looping log is exhausted. `send`
    drops the frame and counts it in `dropped_sends` (nobody listens on a recording).

    A candump ``.log`` is read line by line through python-can's candump parser: a line
    it cannot parse (garbled hex or timestamp, no ``#``, binary junk, an extra field) is
    skipped, counted in `line_errors` (``bad_line``) and logged with its line number
    (rate-limited). Other formats are read by python-can's reader as a whole, which
    cannot go on after a bad record: the rest of that pass is skipped and counted
    (``bad_record``). A frame whose stamp is not finite is skipped (``bad_stamp``); one
    more than 10 s after the previous frame, or before it, is re-based one radar cycle
    after it, with the frames that follow (``stamp_jump``): the replay never waits for a
    time that will not come.
    """

    line_error_prefix = REPLAY    # the shell counts `line_errors` as ``replay_<reason>``

    def __init__(
        self, path: str, pace: Pace = Pace.REALTIME, loop: bool = False,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep, log_name: str = "replay",
    ) -> None:
        self.path = path
        self.pace = pace
        self.loop = loop
        self.ended = False
        self.loops = 0
        self.dropped_sends = 0
        self.line_errors = ReasonCounter()
        self._rl = RateLimitedLog(logging.getLogger(log_name))
        self._clock = clock
        self._sleep = sleep
        self._offset = 0.0
        self._first_t: float | None = None
        self._first_t_raw = 0.0
        self._last_t = 0.0
        self._start_clock = 0.0
        self._pending: can.Message | None = None
        self._reader: can.io.generic.MessageReader | None = None
        self._frames = self._open()

    def _open(self) -> Iterator[can.Message]:
        self._close_reader()
        if Path(self.path).suffix.lower() == ".log":
            return self._candump_lines()
        self._reader = can.LogReader(self.path)
        return self._guarded(iter(self._reader))

    def _candump_lines(self) -> Iterator[can.Message]:
        with open(self.path, "rb") as f:
            for number, raw in enumerate(f, 1):
                try:
                    frames = list(CanutilsLogReader(io.StringIO(raw.decode("ascii"))))
                except _BAD_RECORD as exc:
                    self._bad("bad_line", line=number, text=raw[:80], error=exc)
                    continue
                yield from frames

    def _guarded(self, frames: Iterator[can.Message]) -> Iterator[can.Message]:
        try:
            yield from frames
        except _BAD_RECORD as exc:
            self._bad("bad_record", error=exc)

    def _bad(self, reason: str, **fields: object) -> None:
        self.line_errors.add(reason)
        self._rl.warning(reason, f"replay_{reason}", file=self.path,
                         total=self.line_errors.get(reason), **fields)

    def _close_reader(self) -> None:
        frames = getattr(self, "_frames", None)
        if frames is not None and hasattr(frames, "close"):
            frames.close()      # a generator: closes the file it reads
        if self._reader is not None:
            self._reader.stop()
            self._reader = None

    def _next(self) -> can.Message | None:
        while True:
            msg = next(self._frames, None)
            if msg is not None:
                if math.isfinite(msg.timestamp):
                    break
                # an infinite wait for its time would stall the replay without a word
                self._bad("bad_stamp", stamp=msg.timestamp, arbitration_id=msg.arbitration_id)
                continue
            if not self.loop or self._first_t is None:
                self.ended = True
                return None
            # Restart the log one cycle after its last frame, on the same time line.
            self.loops += 1
            self._offset = self._last_t + _LOOP_GAP_S - self._first_t_raw
            self._frames = self._open()
        if self._first_t is not None:
            gap = msg.timestamp + self._offset - self._last_t
            if not 0.0 <= gap <= _MAX_STAMP_GAP_S:
                # Re-based one radar cycle after the previous frame, the frames after it
                # with it: the replay goes on at the log's own spacing
                self._bad("stamp_jump", gap_s=round(gap, 3), arbitration_id=msg.arbitration_id)
                self._offset += _LOOP_GAP_S - gap
        if self._first_t is None:
            self._first_t = msg.timestamp
            self._first_t_raw = msg.timestamp
            self._start_clock = self._clock()
        msg.timestamp += self._offset
        self._last_t = msg.timestamp
        return msg

    def recv(self, timeout: float | None = None) -> can.Message | None:
        if self._pending is None and not self.ended:
            self._pending = self._next()
        msg = self._pending
        if msg is None:
            if timeout:
                self._sleep(timeout)   # behave like an idle bus, not a busy loop
            return None
        if self.pace is Pace.REALTIME:
            assert self._first_t is not None
            wait = self._start_clock + (msg.timestamp - self._first_t) - self._clock()
            if wait > 0:
                if timeout is not None and wait > timeout:
                    self._sleep(timeout)
                    return None
                self._sleep(wait)
        self._pending = None
        return msg

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.dropped_sends += 1

    def shutdown(self) -> None:
        self._close_reader()
        self._frames = iter(())
