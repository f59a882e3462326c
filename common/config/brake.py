"""Configuration of the brake service: the `[brake]` table (see docs/brake.md)."""

import enum
import math
from typing import Annotated

import msgspec

from aeb_radar_camera.common.config.base import ServiceConfig
from aeb_radar_camera.common.config.paths import ConfigPath
from aeb_radar_camera.common.config.realtime import RealtimeSettings
from aeb_radar_camera.common.keys import FUSION_BRAKE_CMD
from aeb_radar_camera.common.messages.brake import FailsafePolicy

# Timing settings stay below a minute: longer ones are typos, and timers convert them to
# integer nanoseconds
MAX_MS = 60_000.0
_Ms = Annotated[float, msgspec.Meta(gt=0, le=MAX_MS)]
_MsOrZero = Annotated[float, msgspec.Meta(ge=0, le=MAX_MS)]
_Pct = Annotated[float, msgspec.Meta(ge=0, le=100)]


class AgeClock(enum.Enum):
    """How the age of a command is measured (rejection reason `too_old`)."""

    # receipt minus header.pub_mono_ns: transport age, exact, but only when fusion runs
    # on this host (monotonic clocks of two hosts are not comparable)
    MONOTONIC = "monotonic"
    # local wall clock minus header.stamp_ns (the radar cycle): age of the data, for a
    # brake ECU on another host; needs clocks synchronised well below max_age_ms
    WALL = "wall"


class SerialSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The actuator's serial port (pyserial), reopened with backoff when it vanishes."""

    port: str = "/dev/ttyACM0"
    baudrate: Annotated[int, msgspec.Meta(gt=0)] = 115200
    exclusive: bool = True                    # flock: a second brake process cannot open it

    def __post_init__(self) -> None:
        if not self.port:
            raise ValueError("serial.port must name a device")


class ActuatorSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The link's own timing (docs/actuator-protocol.md)."""

    heartbeat_ms: _Ms = 50.0          # a command line at least this often, even if unchanged
    ttl_ms: Annotated[int, msgspec.Meta(ge=20, le=2000)] = 250   # the actuator's own watchdog
    ack_timeout_ms: _Ms = 150.0       # an unacknowledged line older than this: FAULT
    ack_recover_count: Annotated[int, msgspec.Meta(ge=1)] = 3  # good acks to leave FAULT

    def __post_init__(self) -> None:
        if self.ttl_ms < 2 * self.heartbeat_ms:
            raise ValueError("ttl_ms must be at least two heartbeats (2 * heartbeat_ms)")
        if self.ack_timeout_ms > self.ttl_ms:
            # the actuator would release on its own watchdog before a missing ack is
            # noticed as a FAULT
            raise ValueError(f"ack_timeout_ms ({self.ack_timeout_ms:g}) must not be longer "
                             f"than the actuator's own timeout ttl_ms ({self.ttl_ms})")


class BrakeSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    instance: str = "primary"          # the one fusion instance whose commands count
    deadline_ms: _Ms = 200.0           # no valid command for this long: FAILSAFE
    recover_count: Annotated[int, msgspec.Meta(ge=1)] = 3   # consecutive commands to arm
    min_brake_hold_ms: _MsOrZero = 1000.0
    policy: FailsafePolicy = FailsafePolicy.HOLD
    failsafe_hold_s: Annotated[float, msgspec.Meta(gt=0, le=3600)] = 5.0  # policy `hold`
    failsafe_stop_level_pct: _Pct = 30.0                              # policy `stop`
    age_clock: AgeClock = AgeClock.MONOTONIC
    max_age_ms: _Ms = 100.0
    max_future_ms: _MsOrZero = 5.0
    # Key files (common/command_auth.py) of `instance`, by key id: only commands with a
    # valid MAC of one of them are followed. Two during a key rotation. Required.
    command_keys: tuple[ConfigPath, ...] = ()
    # A published example key (deploy/keys/) is refused when the serial port is a real
    # actuator (not the simulator's pty): anyone can sign commands with it. true accepts
    # it all the same, with a WARNING at every start (a bench, never a road).
    allow_example_key: bool = False
    # An authenticated sequence number may run ahead of the last accepted one by at most
    # 16 + this rate times the time since it (seq_jump otherwise): a jump cannot lock out
    # the stream that follows it.
    max_command_rate_hz: Annotated[float, msgspec.Meta(gt=0, le=10000)] = 200.0
    # Evidence of a healthy stream before arming (and before leaving FAILSAFE): the
    # recover_count consecutive commands must span at least recover_window_ms, each
    # built from radar data younger than max_data_age_ms (a burst of queued commands,
    # e.g. after SIGCONT, is not evidence).
    recover_window_ms: Annotated[float, msgspec.Meta(ge=0, le=60000)] = 300.0
    max_data_age_ms: Annotated[float, msgspec.Meta(gt=0, le=60000)] = 150.0
    serial: SerialSettings = msgspec.field(default_factory=SerialSettings)
    actuator: ActuatorSettings = msgspec.field(default_factory=ActuatorSettings)
    # SCHED_FIFO for the command callback (validate, decide, write) and the Zenoh I/O
    # threads; the deadline timer runs one priority above
    realtime: RealtimeSettings = msgspec.field(default_factory=RealtimeSettings)

    def __post_init__(self) -> None:
        if not math.isfinite(self.failsafe_hold_s):
            raise ValueError("failsafe_hold_s must be finite")
        if self.max_age_ms > self.deadline_ms:
            # a command the brake still accepts as fresh would already have missed the
            # deadline
            raise ValueError(f"max_age_ms ({self.max_age_ms:g}) must not be longer than "
                             f"deadline_ms ({self.deadline_ms:g})")


class BrakeConfig(ServiceConfig, frozen=True, forbid_unknown_fields=True):
    brake: BrakeSettings = msgspec.field(default_factory=BrakeSettings)

    def __post_init__(self) -> None:
        super().__post_init__()
        # the instance becomes a key chunk: reject what could never be subscribed to
        FUSION_BRAKE_CMD.key(self.vehicle, instance=self.brake.instance)
