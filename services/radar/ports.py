"""The radar's CAN frames as python-can messages and back, and its bus: opened, or a log
replayed, as common/can_port.py does it for every service that reads CAN, with the
radar's table name in errors and logs."""

import can

from aeb_radar_camera.common.can_port import (
    REPLAY,
    CanPort,
    ConfigurationError,
    ReplayPort,
    describe,
)
from aeb_radar_camera.common.can_port import check_settings as check_port_settings
from aeb_radar_camera.common.can_port import open_port as open_service_port
from aeb_radar_camera.common.config.can import CanSettings, Pace, ReplaySettings
from aeb_radar_camera.services.radar.ars408.codec import RadarFrame

SERVICE = "radar"

# The radar's users (its shell and main, the simulator's CAN links, the fault tools, the
# benchmarks) import these from here.
__all__ = ["REPLAY", "SERVICE", "CanPort", "ConfigurationError", "Pace", "ReplayPort",
           "check_settings", "describe", "open_port", "radar_frame", "radar_message"]


def radar_message(frame: RadarFrame, timestamp_s: float = 0.0) -> can.Message:
    """A radar frame as python-can's message (a standard 11-bit ID)."""
    return can.Message(timestamp=timestamp_s, arbitration_id=frame.arb_id, data=frame.data,
                       is_extended_id=False)


def radar_frame(msg: can.Message) -> RadarFrame:
    """A python-can message's ID and data as a radar frame."""
    return RadarFrame(msg.arbitration_id, bytes(msg.data))


def check_settings(c: CanSettings, r: ReplaySettings) -> None:
    """`[radar.can]` / `[radar.replay]` settings no retry can fix. Raises
    ConfigurationError."""
    check_port_settings(c, r, SERVICE)


def open_port(c: CanSettings, r: ReplaySettings) -> CanPort:
    """The radar's bus (common.can_port.open_port: raises what it raises)."""
    return open_service_port(c, r, SERVICE)
