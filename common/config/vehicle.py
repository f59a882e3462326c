"""Configuration of the vehicle gateway (`aeb vehicle --config FILE`): the ``[gateway]``
table (``vehicle`` is the vehicle id every config has).

The car's CAN is decoded through its DBC (cantools); each field of the published
messages names the DBC signal it comes from, as ``Message.Signal`` (or the bare signal
name when only one message of the DBC has it), and how the DBC's physical value becomes
the field's unit: ``field = scale * value + offset``. A field without a mapping is not
provided by this car (None in every message); see docs/vehicle.md for each field.
"""

import re
from typing import Annotated

import msgspec

from aeb_radar_camera.common.config.base import ServiceConfig
from aeb_radar_camera.common.config.can import REPLAY, CanSettings, ReplaySettings
from aeb_radar_camera.common.config.paths import ConfigPath
from aeb_radar_camera.common.keys import VEHICLE_PERIOD_S

_NAME = re.compile(r"^[A-Za-z0-9_\-]+$")

PositiveFloat = Annotated[float, msgspec.Meta(gt=0)]
NonNegFloat = Annotated[float, msgspec.Meta(ge=0)]
RateHz = Annotated[float, msgspec.Meta(gt=0, le=1000)]
GEARS = ("park", "reverse", "neutral", "drive")


def signal_names(signal: str | tuple[str, ...]) -> tuple[str, ...]:
    return (signal,) if isinstance(signal, str) else signal


class _Mapped(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """What every mapping has: its signal(s) and how long a value counts as fresh."""

    signal: str | tuple[str, ...]
    max_age_s: PositiveFloat | None = None     # None: the table's signal_max_age_s

    def __post_init__(self) -> None:
        names = signal_names(self.signal)
        if not names or any(not n.strip() for n in names):
            raise ValueError("signal must name at least one DBC signal")
        if len(set(names)) != len(names):
            raise ValueError(f"signal names {names} twice")


class ValueMap(_Mapped, frozen=True, forbid_unknown_fields=True):
    """A number: ``scale * value + offset`` of the signal (of the mean of several, e.g.
    the two rear wheel speeds). A value outside [`min`, `max`] (in the field's unit) is
    rejected and counted (``out_of_range:<field>``), never published."""

    scale: float = 1.0
    offset: float = 0.0
    min: float | None = None
    max: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.scale == 0:
            raise ValueError("scale must not be 0")
        if self.min is not None and self.max is not None and self.max < self.min:
            raise ValueError("max must be >= min")


class FlagMap(_Mapped, frozen=True, forbid_unknown_fields=True):
    """A yes/no: true while the signal's value is above `above` (a switch: 0 / 1; a
    pressure: the bar at which the pedal counts as pressed)."""

    above: float = 0.5

    def __post_init__(self) -> None:
        super().__post_init__()
        if not isinstance(self.signal, str):
            raise ValueError("a flag comes from one signal")


class GearMap(_Mapped, frozen=True, forbid_unknown_fields=True):
    """The gear: the signal's raw values (or the DBC's names for them) to park, reverse,
    neutral or drive. A value the map does not name is counted
    (``unmapped_gear:<raw>``) and not taken."""

    values: dict[str, str] = msgspec.field(default_factory=dict)

    def __post_init__(self) -> None:
        super().__post_init__()
        if not isinstance(self.signal, str):
            raise ValueError("the gear comes from one signal")
        if not self.values:
            raise ValueError("gear.values must map the signal's values to gears")
        bad = sorted(g for g in self.values.values() if g not in GEARS)
        if bad:
            raise ValueError(f"gear.values: {bad} are not gears (one of {', '.join(GEARS)})")


class MotionSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """`vehicle/motion` (EgoMotion): both fields are needed to publish it."""

    publish: bool = True
    rate_hz: RateHz = 1 / VEHICLE_PERIOD_S
    speed: ValueMap | None = None             # m/s, forward positive
    yaw_rate: ValueMap | None = None          # deg/s, left positive
    # The speed signal has no sign (most cars'): negative while the gear is reverse
    # (needs [gateway.driver.gear]).
    reverse_from_gear: bool = False


class DriverSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """`vehicle/driver` (DriverInputs): every field optional (None when not mapped),
    at least one mapped to publish it."""

    publish: bool = True
    rate_hz: RateHz = 1 / VEHICLE_PERIOD_S
    steering_wheel_angle: ValueMap | None = None     # deg, left positive
    steering_wheel_rate: ValueMap | None = None      # deg/s, left positive
    accelerator_pedal: ValueMap | None = None        # %, 0 released .. 100
    kickdown: FlagMap | None = None
    brake_pedal_pressed: FlagMap | None = None
    brake_pressure: ValueMap | None = None           # bar
    gear: GearMap | None = None

    def mapped(self) -> dict[str, ValueMap | FlagMap | GearMap]:
        """The mapped fields by DriverInputs field name."""
        fields = {
            "steering_wheel_angle_deg": self.steering_wheel_angle,
            "steering_wheel_rate_dps": self.steering_wheel_rate,
            "accelerator_pedal_pct": self.accelerator_pedal,
            "kickdown": self.kickdown,
            "brake_pedal_pressed": self.brake_pedal_pressed,
            "brake_pressure_bar": self.brake_pressure,
            "gear": self.gear,
        }
        return {name: m for name, m in fields.items() if m is not None}


class GatewaySettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    name: str = "main"               # vehicle/gateway/<name>/status, health/vehicle/<name>
    dbc: ConfigPath = ""             # the car's DBC (relative to the config file)
    can: CanSettings = msgspec.field(
        default_factory=lambda: CanSettings(channel="can1"))
    replay: ReplaySettings = msgspec.field(default_factory=ReplaySettings)
    # How long a decoded value counts as fresh (each mapping can say otherwise): a few
    # periods of the car's message. A message is published only while all of its
    # signals are fresh.
    signal_max_age_s: PositiveFloat = 0.1
    motion: MotionSettings = msgspec.field(default_factory=MotionSettings)
    driver: DriverSettings = msgspec.field(default_factory=DriverSettings)
    status_period_s: PositiveFloat = 1.0
    stats_period_s: NonNegFloat = 10.0    # a vehicle_stats log line this often (0: never)

    def __post_init__(self) -> None:
        if not _NAME.match(self.name):
            raise ValueError(f"gateway name {self.name!r} must be letters, digits, '_' or '-'")
        if not self.dbc:
            raise ValueError("gateway.dbc must name the car's DBC file")
        if self.can.interface == REPLAY and not self.replay.file:
            raise ValueError("can.interface = 'replay' needs replay.file")
        if not (self.motion.publish or self.driver.publish):
            raise ValueError("the gateway publishes nothing: motion and driver both off")
        motion = self.motion
        if motion.publish and (motion.speed is None or motion.yaw_rate is None):
            raise ValueError("motion needs speed and yaw_rate mapped (or publish = false)")
        if self.driver.publish and not self.driver.mapped():
            raise ValueError("driver needs at least one field mapped (or publish = false)")
        if self.motion.reverse_from_gear and self.driver.gear is None:
            raise ValueError("motion.reverse_from_gear needs driver.gear mapped")


class VehicleConfig(ServiceConfig, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """A gateway needs its car's DBC and mapping: the `[gateway]` table is required."""

    gateway: GatewaySettings
