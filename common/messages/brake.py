"""Messages published by the brake service."""

import enum

import msgspec

from aeb_radar_camera.common.messages.header import Header


class BrakeState(enum.Enum):
    STANDBY = "STANDBY"    # no valid command stream yet, brake released
    ARMED = "ARMED"        # valid commands arriving, not braking
    BRAKING = "BRAKING"    # a brake level is applied
    FAILSAFE = "FAILSAFE"  # command deadline missed: the fail-safe policy applies
    FAULT = "FAULT"        # the actuator does not answer or reports a fault


class FailsafePolicy(enum.Enum):
    HOLD = "hold"          # keep an applied brake for a configured time, keep idle idle
    STOP = "stop"          # apply a configured level
    RELEASE = "release"    # release the brake


class BrakeStatus(msgspec.Struct, frozen=True, gc=False, kw_only=True):
    """Published at >= 10 Hz and on every change of state."""

    header: Header
    state: BrakeState
    reason: str
    instance: str                  # the fusion instance followed
    policy: FailsafePolicy
    last_cmd_seq: int              # -1 before the first valid command
    commanded_level_pct: float     # what the service asks of the actuator now
    actuator_position_pct: float | None
    actuator_state: str            # as reported by the actuator's last acknowledgement
    actuator_connected: bool
    cmd_to_serial_us: float | None  # last command receipt -> bytes written
    radar_to_serial_us: float | None  # last CAN frame -> bytes written (same host only)
    rejected: dict[str, int]       # commands rejected, by reason
    counters: dict[str, int]       # deadline misses, acks, ack timeouts, reconnects, ...
    # Added by the brake service (defaults keep older payloads decodable):
    state_since_mono_ns: int = 0   # brake host's monotonic time `state` was entered
    last_cmd_rx_mono_ns: int = 0   # brake host's monotonic receipt time of the last valid command
    command_state: BrakeState | None = None  # the command stream's state; differs under FAULT
