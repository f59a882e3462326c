"""No counter or field of BrakeStatus may overflow its message type, whatever sequence
numbers the commands carry (counters saturate at MAX_COUNT)."""

import logging

from hypothesis import given, settings
from hypothesis import strategies as st

from aeb_radar_camera.common.config.brake import BrakeConfig
from aeb_radar_camera.common.counters import MAX_COUNT
from aeb_radar_camera.common.messages import BrakeStatus, decode, encode
from aeb_radar_camera.services.brake.shell import BrakeShell
from tests.brake.helpers import keyring
from tests.brake.test_core import Rig

SEQ_MAX = 2**64 - 1   # the largest sequence number a BrakeCommand can carry


def _status_bytes(rig: Rig) -> bytes:
    """BrakeStatus as the shell builds it from this core, encoded."""
    shell = BrakeShell(BrakeConfig(brake=rig.settings), logging.getLogger("test_counters"),
                       keys=keyring())
    shell.core = rig.core
    return encode(shell._status(rig.t))


def test_commands_with_the_largest_sequence_number_never_stop_the_status():
    rig = Rig().armed()
    for _ in range(2):
        next_seq = rig.seq
        rig.send(0.0, seq=SEQ_MAX)
        rig.seq = next_seq                            # the real stream goes on from here
        rig.advance(rig.settings.deadline_ms + 10)    # silence
        rig.stream(3)
    status = decode(_status_bytes(rig), BrakeStatus)
    assert all(0 <= v <= MAX_COUNT for v in status.counters.values())
    assert status.rejected["seq_jump"] == 2      # a jump that far is refused (bounded)
    assert status.last_cmd_seq < 2**32 and status.state.value == "ARMED"


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from([0, 1, SEQ_MAX - 1, SEQ_MAX]) | st.integers(0, SEQ_MAX),
                          st.sampled_from([1.0, 20.0, 250.0])),
                min_size=1, max_size=16))
def test_brake_status_always_encodes(commands: list[tuple[int, float]]) -> None:
    """Any sequence of command sequence numbers, at any spacing."""
    rig = Rig()
    rig.connect()
    for seq, wait_ms in commands:
        rig.send(0.0, seq=seq)
        rig.advance(wait_ms)
    status = decode(_status_bytes(rig), BrakeStatus)
    assert all(0 <= v <= MAX_COUNT for v in status.counters.values())
    assert all(0 <= v <= MAX_COUNT for v in status.rejected.values())
    assert -1 <= status.last_cmd_seq <= SEQ_MAX
