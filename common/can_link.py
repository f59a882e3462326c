"""One CAN port read until stopped, the same way by every service that reads CAN (the
radar, the vehicle gateway): opened through common/can_port.py, reopened with
exponential backoff when it cannot be opened or fails, its state kept (`BusState`:
active, silent, error, reopening, ended), the lines its reader dropped counted, frames
written under a lock from any thread.

The service's shell is the `CanHandler`: it gets every frame, a housekeeping tick every
`housekeeping_ns` (`HOUSEKEEPING_NS` unless the service says otherwise) while frames
flow (at least every `RECEIVE_TIMEOUT_NS` on an idle bus), and a call on every change of
the bus state. Failures of the port are counted in
the service's own `rejected` counter (``bus_failure``, ``error_frame``,
``send_while_closed``, ``send_failed``, and ``<reader>_<reason>`` for dropped lines).
"""

import logging
import threading
from collections.abc import Callable
from typing import Protocol

import can

from aeb_radar_camera.common.can_port import CanPort, describe, open_port
from aeb_radar_camera.common.clock import NS_PER_S, mono_ns, wall_ns
from aeb_radar_camera.common.config.can import CanSettings, ReplaySettings
from aeb_radar_camera.common.counters import ReasonCounter
from aeb_radar_camera.common.log import RateLimitedLog, kv
from aeb_radar_camera.common.messages.radar import BusState
from aeb_radar_camera.common.systemd import Watchdog

# Timeouts, status and bus state are looked at every 10 ms while frames flow; an idle
# bus wakes the loop at least every 50 ms for them. Public: a re-run
# (tools/recording/rerun_radar.py) keeps house on the same schedule.
HOUSEKEEPING_NS = 10_000_000
RECEIVE_TIMEOUT_NS = 50_000_000


class CanHandler(Protocol):
    """What a service does with its bus (its shell)."""

    def opened(self, mono_ns: int) -> None:
        """A port is open (after every reopen too): frames can be written now."""

    def receive(self, msg: can.Message, wall_ns: int, mono_ns: int) -> None:
        """One received frame, at the host's receive times."""

    def tick(self, mono_ns: int, wall_ns: int) -> None:
        """Housekeeping while a port is open."""

    def waiting(self, mono_ns: int, wall_ns: int) -> None:
        """Housekeeping between two attempts to open a lost port."""

    def bus_state_changed(self, mono_ns: int) -> None:
        """`CanLink.bus_state` has just changed."""


class CanLink:
    """The port of one service. `rejected` is the service's counter of what went wrong
    on the bus; `log` its logger."""

    def __init__(
        self,
        can_settings: CanSettings,
        replay: ReplaySettings,
        service: str,
        handler: CanHandler,
        rejected: ReasonCounter,
        port_factory: Callable[[], CanPort] | None = None,
        watchdog: Watchdog | None = None,
        housekeeping_ns: int = HOUSEKEEPING_NS,
    ) -> None:
        self.settings = can_settings
        self.housekeeping_ns = housekeeping_ns
        self.handler = handler
        self.rejected = rejected
        self.watchdog = watchdog or Watchdog(env={})
        self.interface, self.channel = describe(can_settings, replay)
        self.bus_state = BusState.SILENT
        self.reopens = 0
        self.ended = False
        self.last_frame_mono_ns: int | None = None
        self._factory = port_factory or (lambda: open_port(can_settings, replay, service))
        self._log = logging.getLogger(service)
        self._rl = RateLimitedLog(self._log)
        self._port: CanPort | None = None
        self._send_lock = threading.Lock()
        self._error_until = 0
        self._silent_ns = int(can_settings.silent_after_s * NS_PER_S)
        self._error_hold_ns = int(can_settings.error_hold_s * NS_PER_S)
        self._port_errors: dict[int, dict[str, int]] = {}

    # -- the loop -----------------------------------------------------------------------

    def run(self, stop: threading.Event) -> bool:
        """Read until `stop` is set (False) or a non-looping replay ended (True; the
        service then calls `end` once it has finished with what it holds)."""
        backoff = self.settings.reopen_backoff_initial_s
        lost = False
        while not stop.is_set():
            if lost:
                self.handler.waiting(mono_ns(), wall_ns())
                if self.watchdog.wait(stop, backoff):
                    break
                backoff = min(2 * backoff, self.settings.reopen_backoff_max_s)
            try:
                port = self._factory()
            except (can.CanError, OSError, ValueError) as exc:
                self.set_state(BusState.REOPENING, mono_ns())
                self._rl.warning("open", "can_open_failed", interface=self.interface,
                                 channel=self.channel, error=repr(exc), retry_s=backoff)
                lost = True
                continue
            if lost:
                self.reopens += 1
            self._log.info(kv("can_open", interface=self.interface, channel=self.channel))
            if self._serve_port(port, stop):
                return True
            if self.last_frame_mono_ns is not None:
                backoff = self.settings.reopen_backoff_initial_s   # it worked for a while
            lost = True
        return False

    def _serve_port(self, port: CanPort, stop: threading.Event) -> bool:
        """Serve one open port; True when a replay ended, False on stop or bus failure."""
        with self._send_lock:
            self._port = port
        try:
            now = mono_ns()
            self.last_frame_mono_ns = None
            self.set_state(BusState.SILENT, now)
            self.handler.opened(now)
            return self._serve(port, stop)
        except (can.CanError, OSError) as exc:
            self.rejected.add("bus_failure")
            self._log.warning(kv("can_lost", interface=self.interface, channel=self.channel,
                                 error=repr(exc)))
            self.set_state(BusState.REOPENING, mono_ns())
            return False
        finally:
            with self._send_lock:
                self._port = None
            self._count_port_errors(port)
            self._port_errors.pop(id(port), None)
            try:
                port.shutdown()
            except (can.CanError, OSError) as exc:   # a lost bus often cannot say goodbye
                self._log.debug(kv("can_shutdown_failed", error=repr(exc)))

    def _serve(self, port: CanPort, stop: threading.Event) -> bool:
        next_housekeeping = 0
        # The schedule of tools/recording/rerun_radar.py, which re-plays this loop.
        while not stop.is_set():
            msg = port.recv(RECEIVE_TIMEOUT_NS / NS_PER_S)
            mono, wall = mono_ns(), wall_ns()
            if msg is not None:
                self.handler.receive(msg, wall, mono)
            elif getattr(port, "ended", False):
                return True
            if mono >= next_housekeeping:
                self._count_port_errors(port)
                self.handler.tick(mono, wall)
                next_housekeeping = mono + self.housekeeping_ns
        return False

    def _count_port_errors(self, port: CanPort) -> None:
        """Lines the interface dropped (BulkSlcanBus.line_errors, ReplayPort.line_errors)
        into `rejected`, as ``<port's line_error_prefix>_<reason>`` (``slcan_`` when it
        names none): never silent, never a reason to drop the bus."""
        errors = getattr(port, "line_errors", None)
        if errors is None:
            return
        prefix = getattr(port, "line_error_prefix", "slcan")
        seen = self._port_errors.setdefault(id(port), {})
        for reason, n in errors.snapshot().items():
            if n > seen.get(reason, 0):
                self.rejected.add(f"{prefix}_{reason}", n - seen.get(reason, 0))
                seen[reason] = n

    # -- frames and state ---------------------------------------------------------------

    def accept(self, msg: can.Message, mono: int) -> bool:
        """A received frame's news about the bus: False for an error frame (counted as
        ``error_frame``, the state held at error for `error_hold_s`), True for a frame
        the service should look at."""
        if msg.is_error_frame:
            self.rejected.add("error_frame")
            self._error_until = mono + self._error_hold_ns
            self._rl.warning("error_frame", "can_error_frame", channel=self.channel)
            return False
        self.last_frame_mono_ns = mono
        if self.bus_state is not BusState.ACTIVE and mono >= self._error_until:
            self.set_state(BusState.ACTIVE, mono)
        return True

    def current_state(self, mono: int) -> BusState:
        """The state at `mono` from the frames seen so far."""
        if self.ended:
            return BusState.ENDED
        if mono < self._error_until:
            return BusState.ERROR
        last = self.last_frame_mono_ns
        if last is None or mono - last > self._silent_ns:
            return BusState.SILENT
        return BusState.ACTIVE

    def refresh(self, mono: int) -> None:
        """Move to the state at `mono` (a housekeeping step)."""
        self.set_state(self.current_state(mono), mono)

    def set_state(self, state: BusState, mono: int) -> None:
        if state is not self.bus_state:
            self._log.info(kv("bus_state", old=self.bus_state.value, new=state.value))
            self.bus_state = state
            self.handler.bus_state_changed(mono)

    def end(self, mono: int) -> None:
        """The replay is over and the service has published what it held."""
        self.ended = True
        self.set_state(BusState.ENDED, mono)

    # -- writing ------------------------------------------------------------------------

    def send(self, messages: list[can.Message]) -> int:
        """Write frames if a port is open (any thread); returns how many went out."""
        sent = 0
        with self._send_lock:
            port = self._port
            if port is None:
                if messages:
                    self.rejected.add("send_while_closed", len(messages))
                return 0
            for m in messages:
                try:
                    port.send(m)
                    sent += 1
                except (can.CanError, OSError) as exc:
                    self.rejected.add("send_failed")
                    self._rl.warning("send", "can_send_failed", arb_id=hex(m.arbitration_id),
                                     error=repr(exc))
        return sent
