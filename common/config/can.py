"""A CAN bus read through python-can, or a recorded log replayed: the ``can`` and
``replay`` tables of every service that reads CAN (the radar, the vehicle gateway)."""

import enum
from typing import Annotated, Any

import msgspec

from aeb_radar_camera.common.config.paths import ConfigPath

PositiveFloat = Annotated[float, msgspec.Meta(gt=0)]

REPLAY = "replay"       # the `interface` that reads `[<service>.replay] file` instead of a bus


class Pace(enum.Enum):
    REALTIME = "realtime"   # frames at their recorded spacing
    FAST = "fast"           # as fast as the service can read them


class CanSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The python-can bus. `interface` is any python-can interface name (socketcan, slcan,
    socketcand, pcan, kvaser, ...) or ``replay`` (then the service's `replay` table is
    used). `options` are passed to `can.Bus` as keyword arguments (e.g.
    ``sleep_after_open`` for slcan, ``host``/``port`` for socketcand)."""

    interface: str = "socketcan"
    channel: str = "can0"
    bitrate: Annotated[int, msgspec.Meta(ge=0)] = 500_000   # 0: leave the adapter's setting
    options: dict[str, Any] = msgspec.field(default_factory=dict)
    silent_after_s: PositiveFloat = 0.5        # no frame for this long: bus_state = silent
    error_hold_s: PositiveFloat = 1.0          # bus_state = error this long after an error frame
    reopen_backoff_initial_s: PositiveFloat = 0.1
    reopen_backoff_max_s: PositiveFloat = 5.0

    def __post_init__(self) -> None:
        if not self.interface:
            raise ValueError("can.interface must not be empty")
        if self.reopen_backoff_max_s < self.reopen_backoff_initial_s:
            raise ValueError("can.reopen_backoff_max_s must be >= reopen_backoff_initial_s")


class ReplaySettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A recorded log (candump .log, .asc, .blf, ... anything python-can's LogReader reads).
    A relative `file` is relative to the config file's folder."""

    file: ConfigPath = ""
    pace: Pace = Pace.REALTIME
    loop: bool = False
    exit_at_end: bool = False   # exit the service (code 0) when a non-looping replay ends
