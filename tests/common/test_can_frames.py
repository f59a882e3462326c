"""CanFrame <-> python-can message: every field and flag there and back."""

import can
import pytest

from aeb_radar_camera.common.messages.radar import (
    CAN_ERROR,
    CAN_EXTENDED,
    CAN_REMOTE,
    can_frame,
    can_message,
)


@pytest.mark.parametrize("extended, remote, error", [
    (False, False, False), (True, False, False), (False, True, False), (False, False, True)])
def test_a_message_becomes_a_frame_and_back(extended, remote, error):
    data = b"" if remote else bytes(range(8))      # a remote frame carries none
    msg = can.Message(timestamp=12.5, arbitration_id=0x60B, data=data, is_extended_id=extended,
                      is_remote_frame=remote, is_error_frame=error)
    frame = can_frame(msg, rx_wall_ns=1_700_000_000_000_000_000, rx_mono_ns=42)
    assert (frame.timestamp_s, frame.rx_wall_ns, frame.rx_mono_ns, frame.arb_id, frame.data) \
        == (12.5, 1_700_000_000_000_000_000, 42, 0x60B, data)
    assert frame.flags == (CAN_EXTENDED * extended) | (CAN_REMOTE * remote) | (CAN_ERROR * error)
    back = can_message(frame)
    assert back.equals(msg, timestamp_delta=None)
    assert back.timestamp == 12.5 and can_message(frame, 3.0).timestamp == 3.0
