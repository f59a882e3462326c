"""The brake service's I/O shell: feeds the pure core from three threads under one lock.

- the command thread (`brake-commands`): every BrakeCommand sample -> core -> serial
  write, right there (the command path). Zenoh puts the samples into a ring of
  QUEUE_CAPACITY without running any Python (no GIL taken per sample on its receive
  thread), the oldest dropped when it is full: a flood of commands costs the brake only
  what it handles, and the newest command waits at most QUEUE_CAPACITY handlings, never
  the backlog of the flood (`command_queue_full` counts the times the thread found the
  ring full, i.e. dropped older samples; `command_samples` counts those it handled);
- the timer thread (`brake-timer`, one real-time priority above the command path): wakes
  at the core's next due time (deadline expiry, hold end, heartbeat, acknowledgement
  timeout) and at least every TIMER_PERIOD_S, so that silence is detected without any
  message arriving; it also publishes BrakeStatus (at once on a change of state, and at
  the key's nominal rate);
- the serial reader thread (`brake-serial`, at the timer's priority): acknowledgements
  and faults from the actuator, port loss and reopening; it publishes the status owed
  for a command when the actuator acknowledges its line (the timer does at its next
  wake-up, at most TIMER_PERIOD_S later, if no acknowledgement comes first), and builds
  the line most likely written next (`LineAhead`), so that the command path finds it ready.

The timer and the serial link start before the Zenoh session exists (`attach` comes
later, from whatever thread opened the session), so that a silent bus from the very
start already leads to FAILSAFE.
"""

import logging
import threading
from collections import Counter
from collections.abc import Callable, Mapping

import zenoh

from aeb_radar_camera.common import systemd
from aeb_radar_camera.common.bus import Bus, TypedPublisher
from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.command_auth import CommandKey, load_keyring
from aeb_radar_camera.common.config.brake import AgeClock, BrakeConfig
from aeb_radar_camera.common.config.realtime import RealtimeSettings
from aeb_radar_camera.common.counters import saturated
from aeb_radar_camera.common.keys import BRAKE_STATUS, FUSION_BRAKE_CMD
from aeb_radar_camera.common.log import RateLimitedLog, kv
from aeb_radar_camera.common.messages import BrakeState, BrakeStatus, Header
from aeb_radar_camera.common.realtime import ThreadRealtime, apply_process
from aeb_radar_camera.common.systemd import Watchdog
from aeb_radar_camera.services.brake.commands import Rejection
from aeb_radar_camera.services.brake.core import BrakeCore, Outgoing
from aeb_radar_camera.services.brake.protocol import SEQ_MODULO, BadLine, Command, Query, encode
from aeb_radar_camera.services.brake.serial_link import SerialLink

SERVICE = "brake"
INSTANCE = "main"
SOURCE = f"{SERVICE}/{INSTANCE}"
MIN_WAIT_NS = 100_000
TIMER_PERIOD_S = 0.05    # the timer's longest sleep; it also wakes at every due time
STATUS_PERIOD_NS = 100_000_000   # BrakeStatus at least at its key's nominal 10 Hz
_TIMER_PERIOD_NS = round(TIMER_PERIOD_S * 1e9)
QUEUE_CAPACITY = 256        # queued command samples at most; the oldest dropped beyond
MAX_UNKNOWN_IDS_LOGGED = 64   # a flood of made-up key ids is counted, not logged each


class LineAhead:
    """The actuator line of each frame the core sends. `prepare` builds, off the command
    path, the line of the frame most likely sent next; `line` hands it out when the frame
    is that one and builds any other on the spot. Not thread-safe: the shell's lock."""

    def __init__(self) -> None:
        self._ready: tuple[Command, bytes] | None = None

    def line(self, frame: Command | Query) -> bytes:
        ready, self._ready = self._ready, None
        if ready is not None and ready[0] == frame:
            return ready[1]
        return encode(frame)

    def prepare(self, frame: Command) -> None:
        self._ready = (frame, encode(frame))


def next_frame(frame: Command) -> Command:
    """The frame sent after `frame` if nothing changes: the next sequence number."""
    # built directly: dataclasses.replace costs several times more, on every acknowledgement
    return Command((frame.seq + 1) % SEQ_MODULO, frame.level_pct, frame.ttl_ms, frame.mode)


class BrakeShell:
    def __init__(self, cfg: BrakeConfig, log: logging.Logger,
                 watchdog: Watchdog | None = None,
                 keys: Mapping[str, CommandKey] | None = None) -> None:
        """`keys`: the command keys to accept; None: read `brake.command_keys`. Raises
        KeyFileError when those files are missing, unreadable, or for another instance."""
        s = cfg.brake
        if keys is None:
            keys = load_keyring(s.command_keys, s.instance)
        self.watchdog = watchdog or Watchdog(env={})   # fed by the timer loop
        self.cfg = cfg
        self._log = log
        self._rl = RateLimitedLog(log, cfg.log.repeat_interval_s)
        self.errors: Counter[str] = Counter()   # the shell's own faults, in the status
        self._lock = threading.Lock()
        self._cond = threading.Condition(self._lock)
        self.core = BrakeCore(s, FUSION_BRAKE_CMD.key(cfg.vehicle, instance=s.instance),
                              mono_ns(), keys)
        for key in keys.values():
            if key.published:
                log.warning(kv("insecure_example_key", key_id=key.key_id, path=key.path,
                               note="published with the source: demo and simulator only; "
                                    "make your own with `aeb keygen`"))
        self.link = SerialLink(s.serial, self._on_link_up, self._on_link_down, self._on_rx, log)
        self._lines = LineAhead()
        self._unknown_ids: set[str] = set()   # unknown key ids logged (once each)
        self._last_frame: Command | None = None   # the last line written
        self._stopping = False
        self._status_pub: TypedPublisher[BrakeStatus] | None = None
        self._subscriber: zenoh.Subscriber[zenoh.Handler[zenoh.Sample]] | None = None
        self._token: zenoh.LivelinessToken | None = None
        self._status_seq = 0
        self._published_version = -1
        self._last_status_ns = 0
        self._publish_at_ns: int | None = None   # a status is owed at this time
        self._publish_lock = threading.Lock()    # taken before _lock, never inside it
        # command samples handled (under the lock, so that a status never shows one
        # not yet classified): each is a command followed (`commands`), a rejection
        # (`rejected`), or `command_failed`
        self.command_samples = 0
        self.cmd_to_serial_us: float | None = None
        self.radar_to_serial_us: float | None = None
        self._timer = threading.Thread(target=self._timer_loop, name="brake-timer", daemon=True)
        self._drainer: threading.Thread | None = None
        self._rt = ThreadRealtime(s.realtime, log, "brake command callback")
        # The timer and the serial reader one priority above the command path: a flood
        # that keeps the command thread busy delays neither the detection of silence nor
        # the reading of the actuator's acknowledgements (late, they fault the link)
        above = RealtimeSettings(priority=min(99, s.realtime.priority + 1)) \
            if s.realtime.priority > 0 else s.realtime
        self._rt_timer = ThreadRealtime(above, log, "brake timer")
        self._rt_serial = ThreadRealtime(above, log, "brake serial reader")

    # ---- life cycle ---------------------------------------------------------------

    def start(self) -> None:
        self._timer.start()
        self.link.start()

    def attach(self, bus: Bus) -> None:
        """Start serving on the bus: status publisher, command subscription (every
        instance, so that other instances are counted as rejections, not unseen), then
        the liveliness token."""
        publisher = bus.publisher(BRAKE_STATUS)
        with self._lock:
            self._status_pub = publisher
            self._cond.notify()
        self._subscriber = bus.session.declare_subscriber(
            FUSION_BRAKE_CMD.wildcard(self.cfg.vehicle),
            zenoh.handlers.RingChannel(QUEUE_CAPACITY))
        self._drainer = threading.Thread(target=self._drain_loop, args=(self._subscriber,),
                                         name="brake-commands", daemon=True)
        self._drainer.start()
        apply_process(self.cfg.brake.realtime, self._log)
        self._token = bus.declare_health(SERVICE, INSTANCE)
        systemd.status(f"serving: following fusion {self.cfg.brake.instance}")
        self._log.info(kv("brake_ready", instance=self.cfg.brake.instance,
                          port=self.cfg.brake.serial.port,
                          policy=self.cfg.brake.policy.value))

    def stop(self) -> None:
        with self._lock:
            self._stopping = True
            self._cond.notify()
        self._timer.join(timeout=5.0)
        self.link.stop()
        if self._token is not None:
            self._token.undeclare()
        if self._subscriber is not None:
            self._subscriber.undeclare()      # ends the command thread's wait
        if self._drainer is not None:
            self._drainer.join(timeout=5.0)

    # ---- events (each under the lock) -----------------------------------------------

    def _drain_loop(self, sub: zenoh.Subscriber[zenoh.Handler[zenoh.Sample]]) -> None:
        """The command thread: each sample of the ring, in arrival order, handled at once;
        ends when the subscriber is undeclared."""
        self._rt.ensure()
        handler = sub.handler
        while True:
            try:
                batch = [handler.recv()]       # waits without the GIL
                while len(batch) < QUEUE_CAPACITY and (more := handler.try_recv()) is not None:
                    batch.append(more)
            except zenoh.ZError:
                return                         # undeclared: the service is stopping
            if len(batch) >= QUEUE_CAPACITY:
                self.errors["command_queue_full"] += 1
            for sample in batch:
                if sample.kind != zenoh.SampleKind.PUT:
                    continue
                try:
                    self.on_command(sample.payload.to_bytes(), str(sample.key_expr), mono_ns())
                except Exception as exc:  # the command path must outlive a bug
                    self.errors["command_failed"] += 1
                    self._rl.error("command", "command_failed", error=repr(exc))

    def on_command(self, payload: bytes, key: str, rx_mono_ns: int) -> None:
        """The command thread: validate, decide and write to the serial line at once."""
        with self._lock:
            self.command_samples += 1
            before = (self.core.state, self.core.command_state)
            out = self.core.on_command(payload, key, rx_mono_ns, wall_ns())
            if out is not None:
                self._write(out, rx_mono_ns)
            if (self.core.state, self.core.command_state) != before:
                self._status_owed(rx_mono_ns)
            else:
                # Not from here, nor by waking the timer for it: a status published now
                # competes with the line for the CPU. The line's acknowledgement publishes
                # it (serial reader), or the timer's next wake-up if the actuator does not
                # answer.
                self._status_owed(rx_mono_ns, wake_timer=False)
            rejection = self.core.last_rejection
            self._log_transition(before)
            validator = self.core.validator
            unknown = validator.unknown_key_id if rejection is Rejection.UNKNOWN_KEY else None
            opened = validator.revert_level is not None
        if rejection is None:
            return
        self._rl.warning(f"reject:{rejection.value}", "command_rejected",
                         reason=rejection.value, key=key)
        if opened:
            self._rl.error("seq_conflict", "seq_conflict_opened",
                           session=validator.session, level_back_to=validator.revert_level,
                           note="two senders hold the command key in one session: "
                                "neither is followed until one is alone")
        if unknown is not None and unknown not in self._unknown_ids \
                and len(self._unknown_ids) < MAX_UNKNOWN_IDS_LOGGED:
            self._unknown_ids.add(unknown)
            self._log.warning(kv("unknown_command_key", key_id=unknown,
                                 trusted=",".join(sorted(validator.keys))))

    def _on_rx(self, items: list[bytes | BadLine]) -> None:
        with self._lock:
            now = mono_ns()
            before = (self.core.state, self.core.command_state)
            version = self.core.version
            for item in items:
                out = self.core.on_rx(item, now)
                if out is not None:
                    self._write(out, None)
                if self.core.rx_problem is not None:
                    self._rl.warning(f"rx:{self.core.rx_problem}", "actuator_bad_line",
                                     reason=self.core.rx_problem)
            if self.core.version != version:   # a plain acknowledgement changes nothing
                self._status_owed(now)
            self._log_transition(before)
            if self._last_frame is not None:
                # the line is delivered and the next command is a radar cycle away: this
                # thread, awake anyway, builds the next line
                self._lines.prepare(next_frame(self._last_frame))
            owed = self._publish_at_ns is not None
        if owed:
            # the actuator answered: the line is delivered, the status no longer competes
            # with it, and this thread is awake anyway (one wake-up of the timer less)
            self._publish_status(lambda now: self._publish_at_ns is not None)

    def _on_link_up(self) -> None:
        self._on_link(True, "")

    def _on_link_down(self, reason: str) -> None:
        self._on_link(False, reason)

    def _on_link(self, up: bool, reason: str) -> None:
        # the serial reader's first call, before any data (SerialLink: on_up precedes
        # on_data on the same thread): it is real-time from here on
        self._rt_serial.ensure()
        with self._lock:
            before = (self.core.state, self.core.command_state)
            out = self.core.on_link(up, mono_ns(), reason)
            if out is not None:
                self._write(out, None)
            self._status_owed(mono_ns())
            self._log_transition(before)

    # ---- timer ----------------------------------------------------------------------

    def _timer_loop(self) -> None:
        self._rt_timer.ensure()
        with self._lock:
            while not self._stopping:
                try:
                    self._tick()
                except Exception as exc:  # the deadline check must outlive a bug
                    self.errors["timer_tick_failed"] += 1
                    self._rl.error("timer", "timer_tick_failed", error=repr(exc),
                                   state=self.core.state.value,
                                   count=self.errors["timer_tick_failed"])
                    self._log.debug("timer traceback", exc_info=True)
                self.watchdog.feed()
                now = mono_ns()
                wake = now + _TIMER_PERIOD_NS
                if self._status_pub is not None:
                    wake = min(wake, self._last_status_ns + STATUS_PERIOD_NS)
                    if self._publish_at_ns is not None:
                        wake = min(wake, self._publish_at_ns)
                due = self.core.next_due_ns(now)
                if due is not None:
                    wake = min(wake, due)
                # a short wait even when something is due already: never spin holding the lock
                self._cond.wait(max(wake - now, MIN_WAIT_NS) / 1e9)

    def _tick(self) -> None:
        now = mono_ns()
        before = (self.core.state, self.core.command_state)
        out = self.core.on_tick(now)
        if out is not None:
            self._write(out, None)
        self._log_transition(before)
        if self.core.version != self._published_version and self._publish_at_ns is None:
            self._publish_at_ns = now   # changed by this tick (deadline, hold, timeout)
        if self._status_pub is None or not self._status_due(now):
            return
        # publish without the lock: the command path must not wait for Zenoh
        self._lock.release()
        try:
            self._publish_status(self._status_due)
        finally:
            self._lock.acquire()

    def _status_due(self, now: int) -> bool:
        owed = self._publish_at_ns is not None and now >= self._publish_at_ns
        return owed or now - self._last_status_ns >= STATUS_PERIOD_NS

    def _publish_status(self, due: Callable[[int], bool]) -> None:
        """Publish BrakeStatus if `due(now)` still holds. Called without the lock, from the
        timer or the serial reader: `_publish_lock` keeps their statuses in sequence order
        on the bus, and the command path never waits for it."""
        with self._publish_lock:
            with self._lock:
                now = mono_ns()
                publisher = self._status_pub
                if publisher is None or not due(now):
                    return
                status = self._status(now)
                self._published_version = self.core.version
                self._last_status_ns = now
                self._publish_at_ns = None
            try:
                publisher.put(status)
            except zenoh.ZError as exc:   # the session is closing
                self.errors["status_publish_failed"] += 1
                self._rl.error("status", "status_publish_failed", error=repr(exc))

    # ---- helpers (lock held) --------------------------------------------------------

    def _status_owed(self, at_ns: int, wake_timer: bool = True) -> None:
        """Publish BrakeStatus at `at_ns` at the latest; wakes the timer if that is sooner
        than it planned (unless another thread will publish it)."""
        if self._publish_at_ns is None or at_ns < self._publish_at_ns:
            self._publish_at_ns = at_ns
            if wake_timer:
                self._cond.notify()

    def _write(self, out: Outgoing, rx_mono_ns: int | None) -> None:
        if not self.link.write(self._lines.line(out.frame)):
            self.core.on_link(False, mono_ns(), "write failed")
            return
        if isinstance(out.frame, Command):
            self._last_frame = out.frame
        if out.cmd is None or rx_mono_ns is None:
            return
        written = mono_ns()
        self.cmd_to_serial_us = (written - rx_mono_ns) / 1e3
        radar_ns = out.cmd.radar_last_frame_mono_ns
        same_host = self.cfg.brake.age_clock is AgeClock.MONOTONIC
        self.radar_to_serial_us = (
            (written - radar_ns) / 1e3 if same_host and 0 < radar_ns <= written else None
        )

    def _log_transition(self, before: tuple[BrakeState, BrakeState]) -> None:
        core = self.core
        if (core.state, core.command_state) == before:
            return
        quiet = (BrakeState.ARMED, BrakeState.BRAKING, BrakeState.STANDBY)
        level = logging.INFO if core.state in quiet else logging.WARNING
        self._log.log(level, kv("brake_state", old=before[0].value, new=core.state.value,
                                command_state=core.command_state.value, reason=core.reason,
                                level_pct=core.commanded_level_pct))

    def _status(self, now: int) -> BrakeStatus:
        v = self.core.view()
        self._status_seq += 1
        return BrakeStatus(
            header=Header(seq=self._status_seq - 1, source=SOURCE, stamp_ns=wall_ns(),
                          pub_mono_ns=now),
            state=v.state, reason=v.reason, instance=self.cfg.brake.instance,
            policy=self.cfg.brake.policy, last_cmd_seq=v.last_cmd_seq,
            commanded_level_pct=v.commanded_level_pct,
            actuator_position_pct=v.actuator_position_pct, actuator_state=v.actuator_state,
            actuator_connected=v.actuator_connected, cmd_to_serial_us=self.cmd_to_serial_us,
            radar_to_serial_us=self.radar_to_serial_us, rejected=v.rejected,
            counters=saturated({**v.counters, **self.errors,
                                "command_samples": self.command_samples}),
            state_since_mono_ns=v.since_ns,
            last_cmd_rx_mono_ns=v.last_cmd_rx_ns, command_state=v.command_state,
        )
