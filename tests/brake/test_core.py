"""The brake core on a fake clock: every state transition, policy, rejection and link
event, with the lines it would write to the actuator."""

import math

import pytest

from aeb_radar_camera.common.command_auth import CommandSigner
from aeb_radar_camera.common.config.brake import BrakeConfig
from aeb_radar_camera.common.config.loader import parse_config
from aeb_radar_camera.common.keys import FUSION_BRAKE_CMD
from aeb_radar_camera.common.messages import BrakeState, Decision
from aeb_radar_camera.services.brake.commands import RECENT
from aeb_radar_camera.services.brake.core import BrakeCore, Outgoing
from aeb_radar_camera.services.brake.protocol import (
    Ack,
    ActuatorState,
    BadLine,
    Command,
    Fault,
    HostMode,
    Nak,
    Query,
    Report,
    decode,
)
from tests.brake.helpers import SIGNER, TEST_KEY, command, keyring, payload

KEY = FUSION_BRAKE_CMD.key("ego", instance="primary")
OTHER_KEY = FUSION_BRAKE_CMD.key("ego", instance="candidate")
T0 = 5_000_000_000_000
WALL0 = 1_800_000_000_000_000_000
MS = 1_000_000


class Rig:
    """The core plus a well-behaved simulated actuator (acks every line at once unless
    `auto_ack` is off) on a fake clock."""

    def __init__(self, auto_ack: bool = True, **brake: object) -> None:
        # arming evidence over two of this rig's 20 ms periods, unless a test says
        brake.setdefault("recover_window_ms", 40.0)
        self.settings = parse_config({"brake": brake}, BrakeConfig).brake
        self.t = T0
        self.core = BrakeCore(self.settings, KEY, self.t, keyring())
        self.lines: list[tuple[int, Command]] = []
        self.auto_ack = auto_ack
        self.position = 0.0
        self.held_pct = 0          # the level the actuator holds when the host starts
        self.queries: list[int] = []
        self.seq = 0
        self.signer = SIGNER

    @property
    def state(self) -> BrakeState:
        return self.core.state

    @property
    def level(self) -> int:
        return self.lines[-1][1].level_pct

    def _record(self, out: Outgoing | None) -> None:
        if out is None:
            return
        frame = decode(encode_line(out.frame))   # a valid line, checksum included
        assert frame == out.frame
        if isinstance(frame, Query):
            self.queries.append(self.t)
            if self.auto_ack:   # the actuator answers with what it holds
                self.rx(encode_line(Report(self.held_pct, self.position, ActuatorState.OK)))
            return
        assert isinstance(frame, Command)
        self.lines.append((self.t, frame))
        if self.auto_ack:
            self.ack(frame.seq)

    def ack(self, seq: int, state: ActuatorState = ActuatorState.OK) -> None:
        self._record(self.core.on_rx(encode_line(Ack(seq, self.position, state)), self.t))

    def rx(self, item: bytes | BadLine) -> None:
        self._record(self.core.on_rx(item, self.t))

    def tick(self) -> None:
        self._record(self.core.on_tick(self.t))

    def advance(self, ms: float, step_ms: float = 10.0) -> None:
        """Move the clock, ticking every `step_ms` (the timer period) and at due times."""
        end = self.t + round(ms * MS)
        while self.t < end:
            due = self.core.next_due_ns(self.t)
            nxt = min(end, self.t + round(step_ms * MS))
            if due is not None and self.t < due < nxt:
                nxt = due
            self.t = nxt
            self.tick()

    def connect(self) -> None:
        self._record(self.core.on_link(True, self.t))
        self.advance(2 * self.settings.actuator.heartbeat_ms)
        assert self.state is not BrakeState.FAULT, self.core.reason

    def send(self, level: float = 0.0, seq: int | None = None, key: str = KEY,
             age_ms: float = 1.0, **kw: object) -> None:
        seq = self.seq if seq is None else seq
        self.seq = max(self.seq, seq + 1)
        kw.setdefault("signer", self.signer)
        data = payload(seq, level, pub_mono_ns=self.t - round(age_ms * MS),
                       stamp_ns=WALL0 + self.t - T0 - round(age_ms * MS),
                       **kw)  # type: ignore[arg-type]
        self.raw(data, key)

    def raw(self, data: bytes, key: str = KEY) -> None:
        self._record(self.core.on_command(data, key, self.t, WALL0 + self.t - T0))

    def stream(self, n: int, level: float = 0.0, period_ms: float = 20.0) -> None:
        for _ in range(n):
            self.send(level)
            self.advance(period_ms)

    def armed(self) -> "Rig":
        self.connect()
        self.stream(self.settings.recover_count)
        assert self.state is BrakeState.ARMED
        return self


def encode_line(frame: Command | Ack | Fault | Nak | Query | Report) -> bytes:
    from aeb_radar_camera.services.brake.protocol import encode as encode_frame

    return encode_frame(frame)[:-1]


# ---- start-up and the deadline ----------------------------------------------------------

def test_starts_in_fault_until_the_actuator_acknowledges_then_standby():
    rig = Rig()
    assert rig.state is BrakeState.FAULT and "not open" in rig.core.reason
    assert rig.core.on_tick(rig.t) is None            # nothing written without a port
    rig._record(rig.core.on_link(True, rig.t))
    assert rig.lines[0][1].mode is HostMode.FAULT    # written at once on connect
    assert rig.state is BrakeState.FAULT             # one ack is not enough
    rig.advance(100)
    assert rig.state is BrakeState.STANDBY
    assert rig.lines[-1][1] .level_pct == 0 and rig.lines[-1][1].mode is HostMode.STANDBY


def test_silence_from_the_start_is_failsafe_at_the_deadline():
    rig = Rig()
    rig.connect()
    due = rig.core.next_due_ns(rig.t)
    assert due is not None and due <= T0 + 200 * MS
    rig.t = T0 + 200 * MS - 1
    rig.tick()
    assert rig.state is BrakeState.STANDBY
    rig.t += 1
    rig.tick()
    assert rig.state is BrakeState.FAILSAFE
    assert rig.core.since_ns == T0 + 200 * MS
    assert "since start" in rig.core.reason
    assert rig.lines[-1][1].mode is HostMode.FAILSAFE and rig.lines[-1][0] == rig.t


def test_arming_needs_consecutive_commands_and_a_gap_restarts_the_count():
    rig = Rig()
    rig.connect()
    rig.stream(2)
    assert rig.state is BrakeState.STANDBY
    rig.seq += 1                                     # one command lost
    rig.stream(2)
    assert rig.state is BrakeState.STANDBY
    rig.stream(1)
    assert rig.state is BrakeState.ARMED
    assert rig.core.counters["seq_gaps"] == 1


def test_every_valid_command_writes_a_line_at_once():
    rig = Rig().armed()
    n = len(rig.lines)
    rig.send(70.0)
    assert len(rig.lines) == n + 1 and rig.lines[-1][0] == rig.t
    assert rig.lines[-1][1].level_pct == 70 and rig.lines[-1][1].mode is HostMode.BRAKING
    assert rig.state is BrakeState.BRAKING and rig.core.view().last_cmd_seq == rig.seq - 1


def test_deadline_counts_from_the_last_valid_command_not_from_rejected_ones():
    rig = Rig().armed()
    last = rig.t
    rig.send(0.0)
    rig.advance(100)
    rig.send(0.0, key=OTHER_KEY)                     # rejected: does not feed the deadline
    rig.send(0.0, seq=0)                             # old: neither
    due = last + 200 * MS
    next_due = rig.core.next_due_ns(rig.t)
    assert next_due is not None and next_due <= due
    rig.t = due - 1
    rig.tick()
    assert rig.state is BrakeState.ARMED
    rig.t = due
    rig.tick()
    assert rig.state is BrakeState.FAILSAFE
    assert rig.core.since_ns - rig.core.view().last_cmd_rx_ns == 200 * MS


def test_a_late_timer_still_counts_the_miss_when_a_command_arrives_first():
    rig = Rig().armed()
    rig.t += 250 * MS                                # the timer did not run
    rig.send(0.0)
    assert rig.core.counters["deadline_misses"] == 1
    assert rig.state is BrakeState.FAILSAFE


def test_heartbeat_repeats_the_level_with_the_ttl():
    rig = Rig().armed()
    rig.send(40.0)
    start = len(rig.lines)
    rig.advance(150, step_ms=1)                     # no commands for 150 ms
    beats = rig.lines[start:]
    assert len(beats) == 3
    assert all(c.level_pct == 40 and c.ttl_ms == 250 for _, c in beats)
    gaps = [b[0] - a[0] for a, b in zip(rig.lines[start - 1:], beats, strict=False)]
    assert all(g == 50 * MS for g in gaps)


# ---- minimum brake hold -----------------------------------------------------------------

def test_a_brake_request_is_held_for_the_minimum_time():
    rig = Rig(min_brake_hold_ms=300).armed()
    rig.send(60.0)
    asked = rig.t
    rig.advance(20)
    assert rig.core.reason == "brake requested"
    rig.send(30.0)                                   # lower: not before the hold ends
    assert rig.level == 60 and rig.core.reason == "minimum brake hold"
    rig.advance(20)
    rig.send(0.0)
    assert rig.level == 60 and rig.state is BrakeState.BRAKING
    assert rig.core.reason == "minimum brake hold"
    while rig.t < asked + 300 * MS - 20 * MS:
        rig.advance(20)
        rig.send(0.0)
        assert rig.level == 60
    rig.advance(20)                                  # the hold ends on the timer
    assert rig.level == 0 and rig.state is BrakeState.ARMED


def test_a_higher_request_during_a_hold_applies_at_once():
    rig = Rig(min_brake_hold_ms=300).armed()
    rig.send(30.0)
    rig.advance(20)
    rig.send(90.0)
    assert rig.level == 90


# ---- fail-safe policies ------------------------------------------------------------------

@pytest.mark.parametrize("braking", [False, True])
def test_hold_keeps_an_applied_brake_for_the_hold_time_and_idle_stays_idle(braking):
    rig = Rig(policy="hold", failsafe_hold_s=1.0, min_brake_hold_ms=0).armed()
    level = 65.0 if braking else 0.0
    rig.stream(3, level)
    rig.advance(200)
    assert rig.state is BrakeState.FAILSAFE
    entry = rig.core.since_ns
    # the stream comes back at once, asking for nothing: the held brake stays anyway
    n = 0
    while rig.t < entry + 1000 * MS - 20 * MS:
        rig.stream(1, 0.0)
        n += 1
        assert rig.level == math.ceil(level), rig.core.reason
        trusted = not braking and n >= 3             # idle: three commands are enough
        assert rig.state is (BrakeState.ARMED if trusted else BrakeState.FAILSAFE)
        assert rig.lines[-1][1].mode is (HostMode.ARMED if trusted else HostMode.FAILSAFE)
    rig.stream(2, 0.0)
    assert rig.level == 0 and rig.state is BrakeState.ARMED


def test_hold_releases_after_the_hold_time_when_nothing_comes_back():
    rig = Rig(policy="hold", failsafe_hold_s=0.5, min_brake_hold_ms=0).armed()
    rig.stream(2, 50.0)
    entry = rig.core.view().last_cmd_rx_ns + 200 * MS
    rig.advance((entry + 490 * MS - rig.t) / MS)
    assert rig.level == 50 and rig.state is BrakeState.FAILSAFE
    assert rig.core.since_ns == entry
    rig.advance(20)
    assert rig.level == 0 and rig.state is BrakeState.FAILSAFE   # still no commands


def test_stop_applies_the_stop_level_and_never_less_than_the_applied_brake():
    rig = Rig(policy="stop", failsafe_stop_level_pct=35.0).armed()
    rig.advance(200)
    assert rig.state is BrakeState.FAILSAFE and rig.level == 35
    rig.advance(5000)
    assert rig.level == 35                           # no time limit
    rig.stream(3, 0.0)                               # three consecutive: leave FAILSAFE
    assert rig.state is BrakeState.ARMED and rig.level == 0
    rig2 = Rig(policy="stop", failsafe_stop_level_pct=35.0, min_brake_hold_ms=0).armed()
    rig2.stream(1, 80.0)
    rig2.advance(200)
    assert rig2.state is BrakeState.FAILSAFE and rig2.level == 80


def test_release_lets_go_at_once():
    rig = Rig(policy="release", min_brake_hold_ms=1000).armed()
    rig.stream(1, 80.0)
    rig.advance(200)
    assert rig.state is BrakeState.FAILSAFE and rig.level == 0


@pytest.mark.parametrize("policy", ["hold", "stop", "release"])
def test_a_valid_brake_request_in_failsafe_brakes_harder_never_less(policy):
    rig = Rig(policy=policy, failsafe_stop_level_pct=20.0).armed()
    rig.advance(200)
    rig.stream(1, 90.0)                              # one valid command: not yet trusted
    assert rig.state is BrakeState.FAILSAFE and rig.level == 90


@pytest.mark.parametrize("policy", ["hold", "release"])
def test_commands_that_come_back_in_failsafe_and_stop_again_are_a_new_miss(policy):
    """A brake asked by a command in FAILSAFE must not stay forever when that stream
    stops again before it was trusted: the policy starts anew from that level."""
    rig = Rig(policy=policy, failsafe_hold_s=1.0, min_brake_hold_ms=0).armed()
    rig.advance(200)
    assert rig.state is BrakeState.FAILSAFE and rig.level == 0
    rig.stream(2, 80.0)                              # not trusted yet, but applied
    assert rig.level == 80 and rig.state is BrakeState.FAILSAFE
    last_rx = rig.core.view().last_cmd_rx_ns
    rig.advance((last_rx + 200 * MS - rig.t) / MS - 1)
    assert rig.level == 80
    rig.advance(1)
    assert rig.core.counters["deadline_misses"] == 2
    if policy == "hold":
        rig.advance(990)
        assert rig.level == 80                       # held for failsafe_hold_s again
    rig.advance(20)
    assert rig.level == 0 and rig.state is BrakeState.FAILSAFE


def test_leaving_failsafe_needs_consecutive_commands():
    rig = Rig(recover_count=4).armed()
    rig.advance(200)
    rig.stream(3)
    assert rig.state is BrakeState.FAILSAFE
    rig.seq += 1                                     # a gap
    rig.stream(3)
    assert rig.state is BrakeState.FAILSAFE
    rig.stream(1)
    assert rig.state is BrakeState.ARMED
    assert rig.core.counters["failsafe_exits"] == 1


def test_a_restarted_publisher_is_followed_after_silence():
    rig = Rig().armed()
    rig.stream(20)
    rig.advance(200)
    rig.seq = 0                                      # fusion restarted: sequence from 0
    rig.signer = CommandSigner(TEST_KEY, session=2)  # ... in a new session
    rig.stream(3)
    assert rig.state is BrakeState.ARMED
    assert rig.core.counters["stream_restarts"] == 1


def test_a_rewound_or_frozen_sequence_of_the_same_session_never_restarts_the_stream():
    rig = Rig().armed()
    rig.stream(20)
    last = rig.seq - 1
    for _ in range(3):                               # silence, then the same seq again
        rig.advance(250)
        rig.send(0.0, seq=last)
        rig.send(0.0, seq=0)
    assert rig.state is BrakeState.FAILSAFE
    assert rig.core.counters["stream_restarts"] == 0 == rig.core.counters["seq_resyncs"]
    # new commands at old sequence numbers: a second sender in the session, never a restart
    assert rig.core.rejected["seq_conflict"] == 6
    assert rig.core.view().last_cmd_seq == last


# ---- rejections ---------------------------------------------------------------------------

def _assert_unmoved(rig: Rig, before_lines: int, last_seq: int) -> None:
    assert rig.state is BrakeState.ARMED
    assert rig.core.view().last_cmd_seq == last_seq
    assert all(c.level_pct == 0 for _, c in rig.lines[before_lines:])
    assert len(rig.lines) == before_lines             # no line written for a rejection


def test_every_rejection_reason_is_counted_and_moves_nothing():
    rig = Rig(age_clock="monotonic").armed()
    rig.stream(RECENT + 2)
    rig.send(0.0)
    last = rig.seq - 1
    n = len(rig.lines)
    rig.send(100.0, key=OTHER_KEY, instance="candidate")      # another instance's key
    rig.send(100.0, instance="candidate")                     # payload says candidate
    rig.raw(b"\x93\x01garbage")                               # not msgpack of the type
    rig.raw(payload(rig.seq, 100.0)[:-3])                     # truncated
    rig.send(150.0)                                           # level out of range
    rig.send(50.0, decision=Decision.WARNING)                 # level without BRAKE
    rig.send(float("nan"), decision=Decision.BRAKE)
    rig.send(0.0, seq=last)                                   # duplicate (the same bytes)
    rig.send(100.0, seq=last - RECENT - 1)                    # old
    rig.send(100.0, age_ms=101)                               # too old
    rig.send(100.0, age_ms=-10)                               # from the future
    _assert_unmoved(rig, n, last)
    assert rig.core.view().rejected == {
        "wrong_instance": 2, "malformed": 2, "invalid": 3, "duplicate": 1,
        "old_sequence": 1, "too_old": 1, "future_stamp": 1,
    }
    rig.send(0.0, seq=last + 1)                              # the stream goes on
    assert rig.core.view().last_cmd_seq == last + 1


def test_too_old_by_wall_clock_uses_the_radar_stamp():
    rig = Rig(age_clock="wall", max_age_ms=120).armed()
    last = rig.seq - 1
    n = len(rig.lines)
    wall_now = WALL0 + rig.t - T0
    rig.raw(payload(rig.seq, 100.0, pub_mono_ns=0, stamp_ns=wall_now - 121 * MS))
    _assert_unmoved(rig, n, last)
    assert rig.core.rejected["too_old"] == 1
    rig.raw(payload(rig.seq, 0.0, pub_mono_ns=0, stamp_ns=wall_now - 119 * MS))
    assert rig.core.view().last_cmd_seq == last + 1


# ---- the actuator link ----------------------------------------------------------------------

def test_missing_acknowledgements_lead_to_fault_and_recover():
    rig = Rig().armed()
    rig.auto_ack = False
    rig.stream(4, 0.0)                               # 80 ms
    assert rig.state is BrakeState.ARMED
    rig.stream(4, 0.0)                               # oldest unacked now > 150 ms
    assert rig.state is BrakeState.FAULT and "acknowledgement" in rig.core.reason
    assert rig.core.command_state is BrakeState.ARMED
    assert rig.lines[-1][1].mode is HostMode.FAULT
    rig.auto_ack = True
    rig.stream(2, 0.0)
    assert rig.state is BrakeState.FAULT             # two good acks are not enough
    rig.stream(1, 0.0)
    assert rig.state is BrakeState.ARMED
    assert rig.core.counters["ack_timeouts"] >= 1


def test_garbage_and_foreign_acks_never_count_as_acknowledgements():
    rig = Rig().armed()
    rig.auto_ack = False
    acks = rig.core.counters["acks"]
    for _ in range(10):
        rig.send(0.0)
        seq = rig.lines[-1][1].seq
        for item in (BadLine.NOISE, BadLine.PARTIAL, b"$A,1,%d,0.0,OK*0000" % seq,
                     encode_line(Ack(seq + 1000, 0.0, ActuatorState.OK)),
                     encode_line(Nak(seq, BadLine.CRC))):
            rig.rx(item)
        rig.advance(20)
    assert rig.state is BrakeState.FAULT
    assert rig.core.counters["acks"] == acks
    assert rig.core.counters["ack_unexpected"] == 10
    assert rig.core.counters["rx_crc"] == 10 and rig.core.counters["naks"] == 10


def test_a_fault_line_or_a_fault_state_is_fault_until_good_acks():
    rig = Rig().armed()
    rig.rx(encode_line(Fault(3, "motor overcurrent")))
    assert rig.state is BrakeState.FAULT and "3: motor overcurrent" in rig.core.reason
    rig.stream(3)
    assert rig.state is BrakeState.ARMED
    rig.auto_ack = False
    rig.send(0.0)
    rig.ack(rig.lines[-1][1].seq, ActuatorState.FAULT)
    assert rig.state is BrakeState.FAULT and rig.core.actuator_state == "FAULT"


def test_link_loss_is_fault_and_the_level_goes_out_at_once_on_reconnect():
    rig = Rig(min_brake_hold_ms=0).armed()
    rig.send(55.0)
    rig._record(rig.core.on_link(False, rig.t, "read failed: EIO"))
    assert rig.state is BrakeState.FAULT and "EIO" in rig.core.reason
    assert not rig.core.view().actuator_connected
    n = len(rig.lines)
    rig.stream(3, 55.0)
    assert len(rig.lines) == n                       # nothing written without a port
    assert rig.core.command_state is BrakeState.BRAKING
    rig._record(rig.core.on_link(True, rig.t))
    assert rig.lines[-1] == (rig.t, rig.lines[-1][1]) and rig.lines[-1][1].level_pct == 55
    rig.stream(3, 55.0)
    assert rig.state is BrakeState.BRAKING
    assert rig.core.counters["serial_connects"] == 2
    assert rig.core.counters["serial_losses"] == 1


def test_status_version_moves_on_every_change():
    rig = Rig().armed()
    v = rig.core.version
    rig.send(0.0)
    assert rig.core.version > v
    v = rig.core.version
    rig.send(0.0, key=OTHER_KEY)
    assert rig.core.version > v


def test_a_command_never_writes_more_than_one_line():
    rig = Rig().armed()
    out = rig.core.on_command(SIGNER.sign(command(rig.seq, pub_mono_ns=rig.t)), KEY, rig.t,
                              WALL0 + rig.t - T0)
    assert isinstance(out, Outgoing) and out.cmd is not None and out.cmd.header.seq == rig.seq


def test_each_line_carries_the_next_sequence_number_the_level_and_the_mode():
    rig = Rig().armed()
    before = rig.lines[-1][1].seq
    rig.send(0.0)
    sent = rig.lines[-1][1]                # decoded, its checksum checked
    assert (sent.seq, sent.level_pct, sent.mode) == (before + 1, 0, HostMode.ARMED)
    rig.send(60.0)
    sent = rig.lines[-1][1]
    assert (sent.seq, sent.level_pct, sent.mode) == (before + 2, 60, HostMode.BRAKING)
    rig.send(60.0)
    sent = rig.lines[-1][1]
    assert (sent.seq, sent.level_pct, sent.mode) == (before + 3, 60, HostMode.BRAKING)


# ---- a host that starts while the actuator holds a brake --------------------------------

def test_a_starting_host_asks_what_the_actuator_holds_before_any_command():
    rig = Rig()
    rig._record(rig.core.on_link(True, rig.t))
    assert rig.queries == [T0] and rig.lines and rig.lines[0][0] == T0
    assert rig.core.view().counters["reports"] == 1


@pytest.mark.parametrize("policy", ["hold", "stop"])
def test_a_host_restarted_mid_stop_never_releases_the_brake(policy):
    rig = Rig(policy=policy, failsafe_hold_s=1.0, min_brake_hold_ms=0)
    rig.held_pct = 100
    rig.connect()
    assert {line.level_pct for _, line in rig.lines} == {100}, "released mid-stop"
    assert rig.state is BrakeState.FAILSAFE and "held 100 %" in rig.core.reason
    rig.stream(3, 100.0)                 # fusion still says BRAKE: followed at 100
    assert rig.level == 100
    assert rig.core.view().counters["restart_holds"] == 1
    if policy == "hold":                 # fusion says NONE: held for failsafe_hold_s
        rig.stream(20, 0.0)
        assert rig.t - T0 < 1000 * MS and rig.level == 100
        rig.stream(40, 0.0)
        assert rig.state is BrakeState.ARMED and rig.level == 0


def test_a_restart_with_nothing_held_starts_released_as_before():
    rig = Rig()
    rig.connect()
    assert {line.level_pct for _, line in rig.lines} == {0}
    assert "restart_holds" not in rig.core.view().counters


def test_an_actuator_that_does_not_know_the_query_gets_commands_at_once():
    rig = Rig(auto_ack=False)
    rig._record(rig.core.on_link(True, rig.t))
    assert rig.queries and not rig.lines
    assert rig.core.on_tick(rig.t) is None              # waiting for the answer
    rig.rx(encode_line(Nak(None, BadLine.TYPE)))
    assert rig.lines and rig.core.view().counters["query_unsupported"] == 1


def test_an_unanswered_query_gives_way_to_commands_after_the_ack_timeout():
    rig = Rig(auto_ack=False)
    rig._record(rig.core.on_link(True, rig.t))
    due = rig.core.next_due_ns(rig.t)
    assert due == T0 + round(rig.settings.actuator.ack_timeout_ms * MS)
    rig.advance(rig.settings.actuator.ack_timeout_ms + 1)
    assert rig.lines and rig.core.view().counters["query_timeouts"] == 1
    assert len(rig.queries) == 1                        # asked once per process
