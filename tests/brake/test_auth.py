"""Only the configured fusion instance moves the brake: authenticated commands, replay,
sequence jumps and sessions (the core on a fake clock), and the evidence of a healthy
stream that arming needs."""

import msgspec
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aeb_radar_camera.common.command_auth import CommandKey, CommandSigner, mac_problem, new_key
from aeb_radar_camera.common.messages import BrakeCommand, BrakeState, decode, encode
from tests.brake.helpers import SIGNER, TEST_KEY, command, keyring
from tests.brake.test_core import KEY, MS, T0, WALL0, Rig

INTRUDER = CommandSigner(CommandKey(TEST_KEY.key_id, "primary", bytes(32)), session=1)


def _unmoved(rig: Rig, lines_before: int, last_seq: int) -> None:
    assert rig.state is BrakeState.ARMED
    assert rig.core.view().last_cmd_seq == last_seq
    assert all(c.level_pct == 0 for _, c in rig.lines[lines_before:])


def _stream_goes_on(rig: Rig) -> None:
    """The real fusion is still in command: its next commands are followed."""
    before = rig.core.counters["commands"]
    rig.stream(3)
    assert rig.core.counters["commands"] == before + 3
    assert rig.state is BrakeState.ARMED
    rig.send(80.0)
    assert rig.state is BrakeState.BRAKING and rig.level == 80


def test_an_unsigned_command_with_a_sequence_ahead_is_refused_and_locks_nothing_out():
    rig = Rig().armed()
    last, n = rig.seq - 1, len(rig.lines)
    for seq in (rig.seq, rig.seq + 10, 2**62, 2**64 - 1):
        rig.send(100.0, seq=seq, signer=None)
        rig.seq = last + 1
    _unmoved(rig, n, last)
    assert rig.core.rejected["unauthenticated"] == 4
    _stream_goes_on(rig)


def test_a_wrong_key_an_unknown_key_id_and_a_changed_byte_are_refused():
    rig = Rig().armed()
    last, n = rig.seq - 1, len(rig.lines)
    rig.raw(INTRUDER.sign(command(rig.seq, 100.0, pub_mono_ns=rig.t)))        # same id
    rig.raw(CommandSigner(new_key("primary")).sign(command(rig.seq, 100.0,
                                                           pub_mono_ns=rig.t)))
    good = SIGNER.sign(command(rig.seq, 0.0, pub_mono_ns=rig.t))
    tampered = good.replace(b"test", b"tesT", 1)                              # the reason
    rig.raw(tampered)
    _unmoved(rig, n, last)
    assert rig.core.rejected["bad_mac"] == 2 and rig.core.rejected["unknown_key"] == 1
    _stream_goes_on(rig)


def test_the_mac_covers_every_field_and_is_the_payloads_last_bytes():
    cmd = command(5, 50.0, pub_mono_ns=T0)
    data = SIGNER.sign(cmd)
    decoded = decode(data, BrakeCommand)
    assert decoded.auth is not None and data.endswith(decoded.auth.mac)
    assert mac_problem(data, decoded, keyring()) is None
    for field, value in (("brake_level_pct", 100.0), ("instance", "primarz"),
                         ("radar_last_frame_mono_ns", 1)):
        forged = encode(msgspec.structs.replace(decoded, **{field: value}))
        assert mac_problem(forged, decode(forged, BrakeCommand), keyring()) == "bad_mac"
    header = msgspec.structs.replace(decoded.header, seq=6)
    forged = encode(msgspec.structs.replace(decoded, header=header))
    assert mac_problem(forged, decode(forged, BrakeCommand), keyring()) == "bad_mac"


def test_a_recorded_command_published_later_is_refused():
    rig = Rig(min_brake_hold_ms=0.0).armed()
    recorded = [SIGNER.sign(command(rig.seq + i, 100.0 if i == 1 else 0.0,
                                    pub_mono_ns=rig.t + i * 20 * MS,
                                    stamp_ns=WALL0 + i * 20 * MS)) for i in range(3)]
    for data in recorded:                            # live: followed once
        rig.raw(data)
        rig.advance(20)
    rig.seq += 3
    rig.stream(5)
    last, n = rig.seq - 1, len(rig.lines)
    for data in recorded:                            # replayed: old stamps
        rig.raw(data)
    assert rig.core.rejected["too_old"] == 3
    rig.advance(300)                                 # even after silence
    for data in recorded:
        rig.raw(data)
    assert rig.core.rejected["too_old"] == 6
    assert rig.core.view().last_cmd_seq == last
    assert all(c.level_pct == 0 for _, c in rig.lines[n:])


def test_a_replay_within_the_age_bound_is_a_duplicate():
    rig = Rig().armed()
    data = SIGNER.sign(command(rig.seq, 0.0, pub_mono_ns=rig.t))
    rig.raw(data)
    rig.raw(data)
    assert rig.core.rejected["duplicate"] == 1


def test_an_authenticated_jump_is_bounded_by_the_time_since_the_last_command():
    rig = Rig(max_command_rate_hz=100.0).armed()
    last, n = rig.seq - 1, len(rig.lines)
    rig.send(100.0, seq=2**62)
    rig.seq = last + 1
    # 20 ms since the last command: 16 + 100 Hz * 20 ms = 18 may be skipped
    rig.send(100.0, seq=last + 1 + 19)
    rig.seq = last + 1
    _unmoved(rig, n, last)
    assert rig.core.rejected["seq_jump"] == 2
    rig.send(0.0, seq=last + 1 + 18)                 # within the bound: a gap
    assert rig.core.counters["seq_gaps"] == 18
    _stream_goes_on(rig)


def test_another_session_of_the_key_is_taken_up_only_once_the_current_one_is_silent():
    rig = Rig().armed()
    other = CommandSigner(TEST_KEY, session=99)
    last = rig.seq - 1
    rig.send(100.0, seq=0, signer=other)
    rig.seq = last + 1
    assert rig.core.rejected["other_session"] == 1
    _stream_goes_on(rig)
    rig.advance(rig.settings.deadline_ms + 10)      # the current session goes silent
    assert rig.state is BrakeState.FAILSAFE
    rig.signer = other
    rig.seq = 0
    rig.stream(3)
    assert rig.core.counters["stream_restarts"] == 1
    assert rig.core.view().last_cmd_seq == 2 and rig.core.rejected["other_session"] == 1


def test_a_flood_of_intruder_commands_between_the_real_ones_moves_nothing():
    rig = Rig().armed()
    for _ in range(50):
        rig.send(0.0)
        real = rig.seq
        for j in range(20):
            rig.send(100.0, seq=real + j * 1000, signer=None)
            rig.send(100.0, seq=real + j, signer=INTRUDER)
        rig.seq = real
        rig.advance(20)
    assert rig.state is BrakeState.ARMED and {c.level_pct for _, c in rig.lines} == {0}
    assert rig.core.rejected["unauthenticated"] == 1000
    assert rig.core.rejected["bad_mac"] == 1000
    _stream_goes_on(rig)


# ---- evidence of a healthy stream (re-arming) --------------------------------------------

@pytest.mark.parametrize("policy", ["hold", "release", "stop"])
def test_a_burst_from_stale_radar_data_after_sigcont_does_not_rearm(policy: str):
    rig = Rig(policy=policy, recover_window_ms=300.0)
    rig.connect()
    rig.stream(20)
    assert rig.state is BrakeState.ARMED
    rig.advance(1000)                                # fusion stopped (SIGSTOP)
    assert rig.state is BrakeState.FAILSAFE
    for age_ms in (1000, 700, 400):                  # SIGCONT: the queued cycles at once
        rig.send(0.0, radar_last_frame_mono_ns=rig.t - age_ms * MS)
        rig.advance(1.5)
    assert rig.state is BrakeState.FAILSAFE
    assert rig.core.counters["stale_data_commands"] == 3


def test_a_burst_of_fresh_commands_is_not_evidence_a_stream_over_the_window_is():
    rig = Rig(recover_window_ms=300.0)
    rig.connect()
    for _ in range(5):                               # five commands within 5 ms
        rig.send(0.0)
        rig.advance(1)
    assert rig.state is BrakeState.STANDBY
    armed_at = None
    for _ in range(30):
        rig.send(0.0)
        if rig.state is BrakeState.ARMED and armed_at is None:
            armed_at = rig.t
        rig.advance(20)
    assert armed_at is not None and armed_at - T0 >= 300 * MS


def test_stale_radar_data_restarts_the_evidence():
    rig = Rig(recover_window_ms=100.0)
    rig.connect()
    for i in range(12):
        stale = i % 4 == 3
        rig.send(0.0, radar_last_frame_mono_ns=rig.t - (500 if stale else 2) * MS)
        rig.advance(20)
    assert rig.state is BrakeState.STANDBY           # never 100 ms of fresh commands
    rig.stream(7)
    assert rig.state is BrakeState.ARMED


def test_the_core_refuses_every_command_without_keys():
    from aeb_radar_camera.common.config.brake import BrakeSettings
    from aeb_radar_camera.services.brake.core import BrakeCore

    core = BrakeCore(BrakeSettings(), KEY, T0, {})
    core.on_command(SIGNER.sign(command(0, pub_mono_ns=T0)), KEY, T0, WALL0)
    assert core.rejected["unknown_key"] == 1


@settings(max_examples=200, deadline=None)
@given(st.binary(min_size=0, max_size=400), st.integers(0, 400), st.integers(0, 255))
def test_no_payload_without_the_key_moves_the_brake(junk: bytes, at: int, xor: int) -> None:
    """Random bytes, and a real signed command with one byte changed: never accepted."""
    rig = Rig().armed()
    last, n = rig.seq - 1, len(rig.lines)
    good = bytearray(SIGNER.sign(command(rig.seq, 100.0, pub_mono_ns=rig.t)))
    if xor:
        good[at % len(good)] ^= xor
        rig.raw(bytes(good))
    rig.raw(junk)
    _unmoved(rig, n, last)
    assert sum(rig.core.rejected.values()) == 1 + (xor != 0)


# ---- a second sender in the session, and a stream that ran ahead (issue: key holders,
# floods) --------------------------------------------------------------------------------

def test_a_key_holder_jumping_ahead_does_not_take_the_stream_over():
    """seq = real + 2 with the key: it may move the brake until the real fusion's next
    command shows a second sender (at most one cycle); then the brake goes back to the
    level it followed before, neither stream moves it, and the real stream is taken up
    again once it is alone."""
    rig = Rig().armed()
    rig.stream(5)
    real = rig.seq
    rig.send(100.0, seq=real + 1)                    # the intruder, ahead of the real fusion
    assert rig.level == 100
    rig.seq = real
    rig.advance(5)
    rig.send(0.0)                                    # the real fusion's next: behind
    assert rig.core.rejected["seq_conflict"] == 1 and rig.level == 0
    n = len(rig.lines)
    for _ in range(10):                              # both keep sending: nobody followed
        rig.advance(10)
        rig.send(100.0, seq=rig.seq + 1)
        rig.advance(10)
        rig.send(0.0, seq=rig.seq - 2)
    assert rig.level == 0 and rig.core.rejected["seq_conflict"] == 21
    assert rig.state is BrakeState.FAILSAFE          # the deadline: a visible refusal
    assert rig.core.rejected.get("old_sequence", 0) == 0
    rig.stream(40)                                   # the intruder stops: the real alone
    assert rig.state is BrakeState.ARMED and rig.core.counters["seq_resyncs"] == 1
    assert {c.level_pct for _, c in rig.lines[n:]} == {0}
    _stream_goes_on(rig)


def test_a_stream_that_ran_far_ahead_while_unfollowed_is_taken_up_at_the_deadline():
    """A fusion flooded into thousands of commands the brake could not follow: its stream
    comes back far ahead; the brake follows it again after the deadline, not minutes."""
    rig = Rig().armed()
    rig.advance(50)
    rig.send(0.0, seq=rig.seq + 20_000)              # alive: a jump, refused
    assert rig.core.rejected["seq_jump"] == 1
    rig.advance(rig.settings.deadline_ms)
    rig.stream(20)
    assert rig.core.counters["seq_resyncs"] == 1 and rig.state is BrakeState.ARMED
    _stream_goes_on(rig)


def test_a_byte_identical_copy_is_a_duplicate_not_a_conflict():
    rig = Rig().armed()
    data = SIGNER.sign(command(rig.seq, 0.0, pub_mono_ns=rig.t))
    rig.raw(data)
    rig.seq += 1
    rig.advance(20)
    rig.send(0.0)
    rig.raw(data)
    assert rig.core.rejected["duplicate"] == 1 and "seq_conflict" not in rig.core.rejected
    _stream_goes_on(rig)
