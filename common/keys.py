"""The single registry of keys: pattern, message type, nominal rate, max age and QoS.

Every publisher and subscriber goes through a `KeySpec`; no service builds a key string
by hand. Keys live under ``aeb/<vehicle>/``.
"""

import enum
import re
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import msgspec

from aeb_radar_camera.common.messages import (
    BrakeCommand,
    BrakeStatus,
    CameraInfo,
    CompressedFrame,
    DepthFrame,
    DriverInputs,
    EgoMotion,
    RadarStatus,
    RadarTracks,
    RawCanFrames,
    VehicleStatus,
    VerifiedTargets,
)

ROOT = "aeb"

T = TypeVar("T", bound=msgspec.Struct)

_CHUNK = re.compile(r"^[A-Za-z0-9_.\-]+$")
_PARAM = re.compile(r"\{(\w+)\}")


class Priority(enum.Enum):
    """Zenoh priorities, highest first (mapped onto zenoh.Priority in common.bus)."""

    REAL_TIME = "REAL_TIME"
    INTERACTIVE_HIGH = "INTERACTIVE_HIGH"
    INTERACTIVE_LOW = "INTERACTIVE_LOW"
    DATA_HIGH = "DATA_HIGH"
    DATA = "DATA"
    DATA_LOW = "DATA_LOW"
    BACKGROUND = "BACKGROUND"


class Congestion(enum.Enum):
    """What a publisher (and every router on the way) does with a sample when the queue
    towards one of its subscribers is full.

    Every key of the registry is DROP. A BLOCK sample waits for the slowest subscriber:
    Zenoh holds the router's reader of the publisher's link (and with it every sample of
    that publisher, of every key and priority) for up to its `wait_before_close` (5 s),
    so any process that subscribes and stops reading (a paused `aeb echo`, a frozen
    recorder) would stop fusion's commands reaching the brake. Dropped, a sample is lost
    for that one subscriber only; the consumers' deadlines cover a lost sample. BLOCK is
    for tools that replay a recording as fast as its readers take it (`aeb replay`).
    """

    BLOCK = "BLOCK"   # never dropped: the publisher waits (see above)
    DROP = "DROP"     # dropped for a subscriber whose queue is full (after 1 ms)


@dataclass(frozen=True)
class QoS:
    priority: Priority = Priority.DATA
    congestion: Congestion = Congestion.DROP
    express: bool = False


@dataclass(frozen=True)
class KeySpec(Generic[T]):
    """One key of the bus.

    `pattern` is relative to ``aeb/<vehicle>/`` and names its parameters in braces.
    `rate_hz` is the nominal publish rate (None: on change or on request); with
    `rate_is_minimum` it is a lower bound ("at least"; the publisher adds samples on
    events). `max_age_s` is how old the newest sample may be before a consumer calls the
    input stale.
    """

    name: str
    pattern: str
    msg_type: type[T] | None
    rate_hz: float | None
    max_age_s: float | None
    qos: QoS
    rate_is_minimum: bool = False

    @property
    def params(self) -> tuple[str, ...]:
        return tuple(_PARAM.findall(self.pattern))

    def key(self, vehicle: str, **params: str) -> str:
        """The concrete key. Raises ValueError on a missing, extra or malformed parameter."""
        expected = set(self.params)
        if set(params) != expected:
            raise ValueError(
                f"key {self.name!r} needs parameters {sorted(expected)}, got {sorted(params)}"
            )
        for name, value in [("vehicle", vehicle), *params.items()]:
            if not _CHUNK.match(value):
                raise ValueError(
                    f"key {self.name!r}: {name}={value!r} must be one key chunk "
                    "(letters, digits, '_', '-', '.')"
                )
        return f"{ROOT}/{vehicle}/" + self.pattern.format(**params)

    def wildcard(self, vehicle: str, **params: str) -> str:
        """A key expression matching every value of the parameters not given."""
        filled = {p: params.get(p, "*") for p in self.params}
        return f"{ROOT}/{vehicle}/" + self.pattern.format(**filled)

    def match(self, key: str, vehicle: str) -> dict[str, str] | None:
        """The parameters of a concrete key of this spec, or None when it does not match."""
        regex = re.escape(f"{ROOT}/{vehicle}/")
        for part in re.split(r"(\{\w+\})", self.pattern):
            m = _PARAM.fullmatch(part)
            regex += f"(?P<{m.group(1)}>[^/]+)" if m else re.escape(part)
        found = re.fullmatch(regex, key)
        return found.groupdict() if found else None


RADAR_CYCLE_S = 0.075

RADAR_TRACKS: KeySpec[RadarTracks] = KeySpec(
    "radar_tracks", "radar/{sensor}/tracks", RadarTracks,
    rate_hz=1 / RADAR_CYCLE_S, max_age_s=2 * RADAR_CYCLE_S + 0.01,
    qos=QoS(Priority.DATA_HIGH, Congestion.DROP, express=True),
)
RADAR_STATUS: KeySpec[RadarStatus] = KeySpec(
    "radar_status", "radar/{sensor}/status", RadarStatus,
    rate_hz=1.0, max_age_s=3.0, qos=QoS(Priority.DATA, Congestion.DROP),
    rate_is_minimum=True,      # 1 Hz and on every change
)
CAMERA_JPEG: KeySpec[CompressedFrame] = KeySpec(
    "camera_jpeg", "camera/{camera}/jpeg", CompressedFrame,
    rate_hz=30.0, max_age_s=0.1, qos=QoS(Priority.DATA, Congestion.DROP),
)
# Depth aligned to the JPEG frames, at the rate the camera publishes it (at most the
# frames'; docs/camera.md). Dropped rather than queued, like the frames.
CAMERA_DEPTH: KeySpec[DepthFrame] = KeySpec(
    "camera_depth", "camera/{camera}/depth", DepthFrame,
    rate_hz=30.0, max_age_s=0.1, qos=QoS(Priority.DATA, Congestion.DROP),
)
CAMERA_INFO: KeySpec[CameraInfo] = KeySpec(
    "camera_info", "camera/{camera}/info", CameraInfo,
    rate_hz=1.0, max_age_s=3.0, qos=QoS(Priority.DATA, Congestion.DROP),
)
FUSION_TARGETS: KeySpec[VerifiedTargets] = KeySpec(
    "fusion_targets", "fusion/{instance}/targets", VerifiedTargets,
    rate_hz=1 / RADAR_CYCLE_S, max_age_s=2 * RADAR_CYCLE_S + 0.01,
    qos=QoS(Priority.DATA_HIGH, Congestion.DROP),
)
FUSION_BRAKE_CMD: KeySpec[BrakeCommand] = KeySpec(
    "fusion_brake_cmd", "fusion/{instance}/brake_cmd", BrakeCommand,
    rate_hz=1 / RADAR_CYCLE_S, max_age_s=0.2,
    qos=QoS(Priority.REAL_TIME, Congestion.DROP, express=True),
)
BRAKE_STATUS: KeySpec[BrakeStatus] = KeySpec(
    "brake_status", "brake/status", BrakeStatus,
    rate_hz=10.0, max_age_s=0.3, qos=QoS(Priority.INTERACTIVE_HIGH, Congestion.DROP),
    rate_is_minimum=True,      # at least 10 Hz, also on every command (13.3 Hz)
)
# The vehicle's own state (docs/vehicle.md): the newest sample is all that counts, so
# dropped rather than queued; a consumer calls a key stale after five periods without one
# (common/vehicle_state.py).
VEHICLE_PERIOD_S = 0.02
EGO_MOTION: KeySpec[EgoMotion] = KeySpec(
    "ego_motion", "vehicle/motion", EgoMotion,
    rate_hz=1 / VEHICLE_PERIOD_S, max_age_s=5 * VEHICLE_PERIOD_S,
    qos=QoS(Priority.DATA_HIGH, Congestion.DROP),
)
VEHICLE_DRIVER: KeySpec[DriverInputs] = KeySpec(
    "vehicle_driver", "vehicle/driver", DriverInputs,
    rate_hz=1 / VEHICLE_PERIOD_S, max_age_s=5 * VEHICLE_PERIOD_S,
    qos=QoS(Priority.DATA_HIGH, Congestion.DROP),
)
VEHICLE_STATUS: KeySpec[VehicleStatus] = KeySpec(
    "vehicle_status", "vehicle/gateway/{gateway}/status", VehicleStatus,
    rate_hz=1.0, max_age_s=3.0, qos=QoS(Priority.DATA, Congestion.DROP),
    rate_is_minimum=True,      # 1 Hz and on every change
)
# The radar's raw CAN frames, per bus, for recordings that re-run the radar. Dropped
# rather than queued when the link is congested: the radar's CAN loop must never wait.
RADAR_CAN: KeySpec[RawCanFrames] = KeySpec(
    "radar_can", "can/{bus}/frames", RawCanFrames,
    rate_hz=1 / RADAR_CYCLE_S, max_age_s=2 * RADAR_CYCLE_S + 0.01,
    qos=QoS(Priority.DATA, Congestion.DROP),
)
# Liveliness tokens (Bus.declare_health): Zenoh's own declarations, sent with the QoS
# Zenoh gives them; this QoS is not used.
HEALTH: KeySpec[Any] = KeySpec(
    "health", "health/{service}/{instance}", None,
    rate_hz=None, max_age_s=None, qos=QoS(),
)

REGISTRY: dict[str, KeySpec[Any]] = {
    spec.name: spec
    for spec in (
        RADAR_TRACKS, RADAR_STATUS, CAMERA_JPEG, CAMERA_DEPTH, CAMERA_INFO,
        FUSION_TARGETS, FUSION_BRAKE_CMD, BRAKE_STATUS, EGO_MOTION, VEHICLE_DRIVER,
        VEHICLE_STATUS, HEALTH, RADAR_CAN,
    )
}
