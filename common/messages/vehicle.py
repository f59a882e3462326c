"""The vehicle's own state on the bus (from the vehicle gateway reading the car's CAN, or
from the simulator), and the gateway's health.

Signs follow ISO 8855: x forward, y left, angles and rates counter-clockwise (left)
positive. A field that is None is one this car's gateway does not provide (its mapping
names no signal for it): a stated absence, never a default.
"""

import enum

import msgspec

from aeb_radar_camera.common.messages.header import Header
from aeb_radar_camera.common.messages.radar import BusState


class EgoMotion(msgspec.Struct, frozen=True, gc=False):
    """Ego speed (forward positive, reverse negative) and yaw rate (left positive).
    From the gateway, `header.stamp_ns` is when the newest of the values was received
    from the car (each of the others within its own bound before it)."""

    header: Header
    speed_mps: float
    yaw_rate_dps: float


class Gear(enum.Enum):
    """The gear selector (any forward gear of a manual gearbox is `drive`)."""

    PARK = "park"
    REVERSE = "reverse"
    NEUTRAL = "neutral"
    DRIVE = "drive"


class DriverInputs(msgspec.Struct, frozen=True, gc=False, kw_only=True):
    """What the driver does with the wheel, the pedals and the gear selector.
    `header.stamp_ns`: when the newest of the values was received from the car (each of
    the others within its own bound before it)."""

    header: Header
    steering_wheel_angle_deg: float | None      # left positive, 0 straight ahead
    steering_wheel_rate_dps: float | None       # left positive
    accelerator_pedal_pct: float | None         # 0 released .. 100 floored
    kickdown: bool | None                       # the pedal's kick-down switch
    brake_pedal_pressed: bool | None
    brake_pressure_bar: float | None            # master cylinder (driver's) pressure
    gear: Gear | None


class SignalHealth(msgspec.Struct, frozen=True, gc=False, kw_only=True):
    """One CAN signal the gateway maps: `signal` is ``Message.Signal`` in the DBC,
    `field` the message field it feeds (``motion.speed_mps``). `age_s` is None until
    the signal was first received."""

    signal: str
    field: str
    age_s: float | None
    fresh: bool


class VehicleStatus(msgspec.Struct, frozen=True, gc=False, kw_only=True):
    """The vehicle gateway's health: published at `status_period_s` and on every change
    of `ready`, `not_ready_reason` or `bus_state`.

    `ready` iff the CAN bus is active and every mapped signal is fresh (a message is
    published only while every signal it is made of is fresh). `published` and
    `withheld` count messages by key (withheld: due but not sent because a signal was
    stale or never received). `rejected`: frames and values the gateway could not use,
    by reason (``decode_error``, ``out_of_range:<field>``, ``not_finite:<field>``,
    ``unmapped_gear:<raw>``, ``remote_frame``, ``internal_error``, and the bus's own:
    ``bus:error_frame``, ``bus:replay_bad_line``, ...). `ignored`: frames that are not
    the gateway's business (``not_in_dbc``, ``no_mapped_signal``)."""

    header: Header
    gateway: str
    ready: bool
    not_ready_reason: str          # empty when ready
    bus_state: BusState
    interface: str                 # python-can interface name, or "replay"
    channel: str
    dbc: str                       # the DBC file's name
    frames_per_s: float
    frames_total: int
    frames_decoded: int
    bus_reopens: int
    signals: tuple[SignalHealth, ...]
    published: dict[str, int]
    withheld: dict[str, int]
    rejected: dict[str, int]
    ignored: dict[str, int]
