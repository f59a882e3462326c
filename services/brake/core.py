"""The brake service's decisions. Pure: events and the current monotonic time (ns) in, at
most one actuator line out per event; no Zenoh, no serial, no clocks.

Two halves make the reported state (docs/brake.md has the diagram):

- the command stream: STANDBY (not yet trusted), ARMED / BRAKING (trusted, following
  the configured fusion instance), FAILSAFE (the deadline was missed; the policy
  applies until `recover_count` consecutive valid commands arrive again);
- the actuator link: healthy, or a fault (port lost, acknowledgements missing, the
  actuator reports a fault) that shows as FAULT over whatever the stream's state is.

The level sent to the actuator never depends on the link's health: when the link comes
back the current level goes out at once.
"""

from collections import Counter, deque
from collections.abc import Mapping
from dataclasses import dataclass

from aeb_radar_camera.common.command_auth import CommandKey
from aeb_radar_camera.common.config.brake import BrakeSettings
from aeb_radar_camera.common.counters import saturated
from aeb_radar_camera.common.messages import BrakeCommand, BrakeState, Decision, FailsafePolicy
from aeb_radar_camera.services.brake.commands import Accepted, CommandValidator, Rejection
from aeb_radar_camera.services.brake.protocol import (
    SEQ_MODULO,
    Ack,
    ActuatorState,
    BadLine,
    Command,
    Fault,
    HostMode,
    Nak,
    ProtocolError,
    Query,
    Report,
    decode,
    level_to_wire,
)

HOST_ACCEPTS = frozenset("AFNR")
MAX_UNACKED = 64

_MODE = {
    BrakeState.STANDBY: HostMode.STANDBY,
    BrakeState.ARMED: HostMode.ARMED,
    BrakeState.BRAKING: HostMode.BRAKING,
    BrakeState.FAILSAFE: HostMode.FAILSAFE,
    BrakeState.FAULT: HostMode.FAULT,
}


def _ns(ms: float) -> int:
    return round(ms * 1_000_000)


@dataclass(frozen=True, slots=True)
class Outgoing:
    """A line to write to the actuator now: a command, or the query a starting host
    sends before any command."""

    frame: Command | Query
    cmd: BrakeCommand | None   # the accepted command that caused it (None: timer, link)


@dataclass(frozen=True)
class CoreView:
    """What BrakeStatus reports, taken under the shell's lock."""

    state: BrakeState
    command_state: BrakeState
    reason: str
    since_ns: int
    last_cmd_seq: int
    last_cmd_rx_ns: int
    commanded_level_pct: float
    actuator_position_pct: float | None
    actuator_state: str
    actuator_connected: bool
    rejected: dict[str, int]
    counters: dict[str, int]


class BrakeCore:
    def __init__(self, settings: BrakeSettings, expected_key: str, now_ns: int,
                 keys: Mapping[str, CommandKey]) -> None:
        """`keys`: the command keys of `settings.instance`, by key id."""
        s = self.settings = settings
        self._deadline = _ns(s.deadline_ms)
        self._min_hold = _ns(s.min_brake_hold_ms)
        self._fs_hold = _ns(s.failsafe_hold_s * 1000.0)
        self._heartbeat = _ns(s.actuator.heartbeat_ms)
        self._ack_timeout = _ns(s.actuator.ack_timeout_ms)
        self._ttl_ms = s.actuator.ttl_ms
        self.validator = CommandValidator(
            expected_key, s.instance, s.age_clock, _ns(s.max_age_ms), _ns(s.max_future_ms),
            keys, s.max_command_rate_hz, conflict_ns=_ns(s.deadline_ms),
        )
        self._recover_window = _ns(s.recover_window_ms)
        self._max_data_age = _ns(s.max_data_age_ms)
        self.rejected: Counter[str] = Counter()
        self.counters: Counter[str] = Counter()
        self.version = 0      # bumped on every change that deserves a status at once
        self.last_rejection: Rejection | None = None   # of the latest on_command
        self.rx_problem: str | None = None             # of the latest on_rx

        # command stream
        self._start_ns = now_ns
        self._last_rx: int | None = None
        self._last_seq = -1
        self._consecutive = 0
        self._streak_start = now_ns    # receipt of the first command of the current streak
        self._trusted = False
        self._requested = 0.0
        self._held_level = 0.0
        self._held_until = now_ns
        self._failsafe = False
        self._rx_in_failsafe = False   # a command was accepted since FAILSAFE was entered
        self._fs_level = 0.0
        self._fs_hold_end = now_ns
        self._fs_why = ""

        # actuator link
        self._link_up = False
        self._fault: str | None = "serial port not open yet"
        self._ok_acks = 0
        self._tx_seq = 0
        self._unacked: deque[tuple[int, int]] = deque()
        self._last_tx_ns: int | None = None
        self._last_tx: tuple[int, HostMode] | None = None
        # A starting host asks what the actuator holds before it commands anything (a
        # restart mid-stop must not release it): sent at the first link-up only, waited
        # for up to the ack timeout; an actuator that does not know the query says TYPE
        self._queried = False
        self._query_sent_ns: int | None = None
        self.ack_rtt_ns: int | None = None
        self.position_pct: float | None = None
        self.actuator_state = "disconnected"

        # reported
        self.command_state = BrakeState.STANDBY
        self.state = BrakeState.FAULT
        self.reason = self._fault
        self.since_ns = now_ns
        self._wire_level = 0
        self._report: tuple[object, ...] = ()
        self._evaluate(now_ns)

    # ---- events -------------------------------------------------------------------

    def on_command(
        self, payload: bytes, key: str, rx_mono_ns: int, rx_wall_ns: int
    ) -> Outgoing | None:
        """A sample from the bus. Rejected commands are counted and change nothing else."""
        now = rx_mono_ns
        if self._deadline_missed(now):
            self._evaluate(now)  # the deadline passed before the timer noticed: still a miss
        alive = self._last_rx is not None and now - self._last_rx < self._deadline
        result = self.validator.check(payload, key, now, rx_wall_ns, alive)
        self.last_rejection = result if isinstance(result, Rejection) else None
        if isinstance(result, Rejection):
            self.rejected[result.value] += 1
            self.version += 1
            if self.validator.revert_level is not None and self._revert(
                    self.validator.revert_level, now):
                self._evaluate(now)
                return self._send(now, None)
            return self._send_if_due(now)
        self._accept(result, now, alive)
        self._evaluate(now)
        return self._send(now, result.cmd)

    def on_tick(self, now: int) -> Outgoing | None:
        """The timer: deadline, holds, acknowledgement timeout, heartbeat."""
        self._evaluate(now)
        return self._send_if_due(now)

    def on_rx(self, item: bytes | BadLine, now: int) -> Outgoing | None:
        """A line (or a discarded run of bytes) from the actuator."""
        self.rx_problem = None
        if isinstance(item, BadLine):
            self.rx_problem = item.value
            self.counters[f"rx_{item.value}"] += 1
            return None
        try:
            frame = decode(item, HOST_ACCEPTS)
        except ProtocolError as exc:
            self.rx_problem = exc.reason.value
            self.counters[f"rx_{exc.reason.value}"] += 1
            return None
        if isinstance(frame, Ack):
            self._on_ack(frame, now)
        elif isinstance(frame, Fault):
            self.counters["fault_lines"] += 1
            self._ok_acks = 0
            self._fault = f"actuator fault {frame.code}: {frame.text}"
        elif isinstance(frame, Report):
            self._on_report(frame, now)
        elif isinstance(frame, Nak):
            self.counters["naks"] += 1
            self.counters[f"nak_{frame.reason.value}"] += 1
            if self._query_sent_ns is not None and frame.reason is BadLine.TYPE:
                self.counters["query_unsupported"] += 1
                self._query_sent_ns = None
        self._evaluate(now)
        return self._send_if_due(now)

    def on_link(self, up: bool, now: int, detail: str = "") -> Outgoing | None:
        """The serial port opened (up) or was lost. Idempotent."""
        if up == self._link_up:
            return None
        self._link_up = up
        self._query_sent_ns = None
        self._unacked.clear()
        self._ok_acks = 0
        self._last_tx = None
        self._last_tx_ns = None
        if up:
            self.counters["serial_connects"] += 1
            self._fault = "serial port open, waiting for acknowledgements"
            self.actuator_state = "unknown"
        else:
            self.counters["serial_losses"] += 1
            self._fault = f"serial port lost: {detail}" if detail else "serial port lost"
            self.actuator_state = "disconnected"
            self.position_pct = None
        self._evaluate(now)
        if up and not self._queried:
            self._queried = True
            self._query_sent_ns = now
            self.counters["queries"] += 1
            return Outgoing(Query(), None)
        return self._send(now, None)

    def next_due_ns(self, now: int) -> int | None:
        """When `on_tick` must run next at the latest (None: nothing pending)."""
        due: list[int] = []
        if not self._failsafe or self._rx_in_failsafe:
            due.append((self._last_rx if self._last_rx is not None else self._start_ns)
                       + self._deadline)
        if self._held_until > now:
            due.append(self._held_until)
        if self._failsafe and self._fs_hold_end > now:
            due.append(self._fs_hold_end)
        if self._query_sent_ns is not None:
            due.append(self._query_sent_ns + self._ack_timeout)
        elif self._link_up:
            due.append(now if self._last_tx_ns is None else self._last_tx_ns + self._heartbeat)
        if self._unacked:
            due.append(self._unacked[0][1] + self._ack_timeout)
        return min(due) if due else None

    @property
    def commanded_level_pct(self) -> float:
        return float(self._wire_level)

    def view(self) -> CoreView:
        return CoreView(
            state=self.state, command_state=self.command_state, reason=self.reason,
            since_ns=self.since_ns, last_cmd_seq=self._last_seq,
            last_cmd_rx_ns=self._last_rx or 0, commanded_level_pct=self.commanded_level_pct,
            actuator_position_pct=self.position_pct, actuator_state=self.actuator_state,
            actuator_connected=self._link_up, rejected=saturated(self.rejected),
            counters=saturated(self.counters),
        )

    # ---- levels -------------------------------------------------------------------

    def _command_level(self, now: int) -> float:
        held = self._held_level if now < self._held_until else 0.0
        return max(self._requested, held)

    def _policy_level(self, now: int) -> float:
        policy = self.settings.policy
        if policy is FailsafePolicy.HOLD:
            return self._fs_level if now < self._fs_hold_end else 0.0
        if policy is FailsafePolicy.STOP:
            return max(self._fs_level, self.settings.failsafe_stop_level_pct)
        return 0.0

    def level(self, now: int) -> float:
        """The level asked of the actuator. In FAILSAFE the policy's level is a floor:
        a valid command may brake harder, never less."""
        level = self._command_level(now)
        if self._failsafe:
            level = max(level, self._policy_level(now))
        return level

    # ---- internals ----------------------------------------------------------------

    def _accept(self, acc: Accepted, now: int, alive: bool) -> None:
        cmd = acc.cmd
        self.counters["commands"] += 1
        if acc.gap:
            self.counters["seq_gaps"] += acc.gap
        if acc.resync:
            self.counters["seq_resyncs"] += 1
        elif acc.restart:
            self.counters["stream_restarts"] += 1
        # evidence of a healthy stream (for arming): consecutive commands built from
        # fresh radar data; a command from stale data ends the streak
        if acc.data_age_ns > self._max_data_age:
            self.counters["stale_data_commands"] += 1
            self._consecutive = 0
        elif alive and acc.gap == 0 and not acc.restart and self._consecutive > 0:
            self._consecutive += 1
        else:
            self._consecutive = 1
            self._streak_start = now
        self._last_rx = now
        self._last_seq = cmd.header.seq
        self._rx_in_failsafe = self._failsafe
        level = cmd.brake_level_pct if cmd.decision is Decision.BRAKE else 0.0
        self._requested = level
        # minimum hold: a level is not lowered until min_brake_hold_ms after it was asked
        if level > 0.0 and (level >= self._held_level or now >= self._held_until):
            self._held_level = level
            self._held_until = now + self._min_hold
        self.version += 1

    def _revert(self, level: float, now: int) -> bool:
        """A second sender in the followed session (SEQ_CONFLICT): back to the level the
        brake followed before it, its minimum hold included; the session's commands are
        refused from now on, so the deadline decides what comes next (FAILSAFE). True
        when the level asked of the actuator changed."""
        self.counters["seq_conflicts_opened"] += 1
        before = self._command_level(now)
        self._requested = level
        self._held_level = min(self._held_level, level)
        self.version += 1
        return self._command_level(now) != before

    def _deadline_missed(self, now: int) -> bool:
        """No valid command for the deadline, with something new to fail: the stream (or
        the start), or commands that came back in FAILSAFE and stopped again."""
        if self._failsafe and not self._rx_in_failsafe:
            return False
        ref = self._last_rx if self._last_rx is not None else self._start_ns
        return now - ref >= self._deadline

    def _enter_failsafe(self, now: int) -> None:
        """Each miss starts the policy anew from the level applied at this moment (in
        FAILSAFE already: including the policy's own level, so a hold is never cut)."""
        had_commands = self._last_rx is not None
        self._fs_level = self.level(now)
        self._fs_hold_end = now + self._fs_hold
        self._failsafe = True
        self._rx_in_failsafe = False
        self._trusted = False
        self._consecutive = 0
        self._requested = 0.0
        self._held_level = 0.0
        self._held_until = now
        self.counters["deadline_misses"] += 1
        self._fs_why = (
            f"no valid command from {self.settings.instance} for "
            f"{self.settings.deadline_ms:g} ms" if had_commands
            else f"no valid command from {self.settings.instance} since start"
        )

    def _hold_blocks_exit(self, now: int) -> bool:
        """Under `hold`, an applied brake is kept for failsafe_hold_s even if the stream
        comes back: never released mid-stop."""
        return (self.settings.policy is FailsafePolicy.HOLD and self._fs_level > 0.0
                and now < self._fs_hold_end)

    def _evaluate(self, now: int) -> None:
        if self._deadline_missed(now):
            self._enter_failsafe(now)
        fresh = self._last_rx is not None and now - self._last_rx < self._deadline
        if (not self._trusted and fresh and self._consecutive >= self.settings.recover_count
                and now - self._streak_start >= self._recover_window
                and not (self._failsafe and self._hold_blocks_exit(now))):
            self._trusted = True
            if self._failsafe:
                self._failsafe = False
                self.counters["failsafe_exits"] += 1
        if self._query_sent_ns is not None and now - self._query_sent_ns >= self._ack_timeout:
            self.counters["query_timeouts"] += 1
            self._query_sent_ns = None
        if self._unacked and now - self._unacked[0][1] >= self._ack_timeout:
            self.counters["ack_timeouts"] += 1
            self._unacked.clear()
            self._ok_acks = 0
            self._fault = (f"no acknowledgement within "
                           f"{self.settings.actuator.ack_timeout_ms:g} ms")
        self._update_report(now)

    def _update_report(self, now: int) -> None:
        level = self.level(now)
        if self._failsafe:
            cmd_state = BrakeState.FAILSAFE
        elif not self._trusted:
            cmd_state = BrakeState.STANDBY
        elif level > 0.0:
            cmd_state = BrakeState.BRAKING
        else:
            cmd_state = BrakeState.ARMED
        state = cmd_state if self._fault is None else BrakeState.FAULT
        wire = level_to_wire(level)
        held = cmd_state is BrakeState.BRAKING and self._requested < level
        report = (state, cmd_state, wire, self._fault, self._fs_why, held)
        if report == self._report:
            return   # the common case on the command path: nothing to re-describe
        self._report = report
        if state is not self.state:
            self.since_ns = now
        self.state, self.command_state, self._wire_level = state, cmd_state, wire
        self.reason = self._describe(cmd_state, held)
        self.version += 1

    def _describe(self, cmd_state: BrakeState, held: bool) -> str:
        s = self.settings
        if self._fault is not None:
            return self._fault
        if cmd_state is BrakeState.FAILSAFE:
            return f"{self._fs_why} (policy {s.policy.value})"
        if cmd_state is BrakeState.STANDBY:
            return (f"waiting for {s.recover_count} consecutive valid commands from "
                    f"{s.instance} over {s.recover_window_ms:g} ms")
        if cmd_state is BrakeState.BRAKING:
            return "minimum brake hold" if held else "brake requested"
        return f"following {s.instance}"

    def _on_ack(self, ack: Ack, now: int) -> None:
        if not any(seq == ack.seq for seq, _ in self._unacked):
            # not a line we are waiting for: never counts as an acknowledgement
            self.counters["ack_unexpected"] += 1
            return
        # acknowledging a line implies the older ones are settled (acked or refused)
        while True:
            seq, sent = self._unacked.popleft()
            if seq == ack.seq:
                break
        self.counters["acks"] += 1
        self.ack_rtt_ns = now - sent
        self.position_pct = ack.position_pct
        self.actuator_state = ack.state.value
        if ack.state is ActuatorState.FAULT:
            self._ok_acks = 0
            if self._fault is None:
                self._fault = "actuator reports FAULT"
            return
        self._ok_acks += 1
        if self._fault is not None and self._ok_acks >= self.settings.actuator.ack_recover_count:
            self._fault = None
            self.counters["fault_recoveries"] += 1

    def _on_report(self, report: Report, now: int) -> None:
        if self._query_sent_ns is None:
            self.counters["report_unexpected"] += 1
            return
        self._query_sent_ns = None
        self.counters["reports"] += 1
        self.position_pct = report.position_pct
        self.actuator_state = report.state.value
        if report.target_pct > 0 and self.settings.policy is not FailsafePolicy.RELEASE:
            # the previous host stopped mid-stop: this one starts where a missed deadline
            # would have left it, holding that level under the fail-safe policy until
            # the stream is trusted again and the hold is over
            self.counters["restart_holds"] += 1
            self._failsafe = True
            self._rx_in_failsafe = False
            self._trusted = False
            self._fs_level = max(self._fs_level, float(report.target_pct))
            self._fs_hold_end = now + self._fs_hold
            self._fs_why = (f"started while the actuator held {report.target_pct} %: "
                            f"not released mid-stop")

    def _send_if_due(self, now: int) -> Outgoing | None:
        if not self._link_up or self._query_sent_ns is not None:
            return None
        if (self._last_tx_ns is None or now - self._last_tx_ns >= self._heartbeat
                or (self._wire_level, _MODE[self.state]) != self._last_tx):
            return self._send(now, None)
        return None

    def _send(self, now: int, cmd: BrakeCommand | None) -> Outgoing | None:
        if not self._link_up or self._query_sent_ns is not None:
            return None
        mode = _MODE[self.state]
        seq = self._tx_seq
        self._tx_seq = (seq + 1) % SEQ_MODULO
        self._unacked.append((seq, now))
        if len(self._unacked) > MAX_UNACKED:
            self._unacked.popleft()
        self._last_tx_ns = now
        self._last_tx = (self._wire_level, mode)
        self.counters["tx_lines"] += 1
        return Outgoing(Command(seq, self._wire_level, self._ttl_ms, mode), cmd)
