"""Settings every service shares: vehicle id, Zenoh connection, logging."""

import enum
import re
from typing import Annotated, Any

import msgspec

from aeb_radar_camera.common.config.paths import ConfigPath

_VEHICLE = re.compile(r"^[A-Za-z0-9_\-]+$")
_ENDPOINT = re.compile(r"^(tcp|udp|tls|quic|unixsock-stream|ws)/.+")


class ZenohMode(enum.Enum):
    CLIENT = "client"
    PEER = "peer"
    ROUTER = "router"


class ZenohSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """How a process joins the bus.

    `config_file` (Zenoh JSON5, relative to the service's config file) is read first; the
    fields below override it; `overrides` are raw Zenoh config keys
    (``"transport/unicast/max_links"``) applied last.
    Multicast scouting stays off unless `multicast_scouting` is true.
    """

    mode: ZenohMode = ZenohMode.CLIENT
    connect: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    listen: tuple[str, ...] = ()
    config_file: ConfigPath = ""
    multicast_scouting: bool = False
    gossip_scouting: bool = False
    overrides: dict[str, Any] = msgspec.field(default_factory=dict)

    def __post_init__(self) -> None:
        for ep in (*self.connect, *self.listen):
            if not _ENDPOINT.match(ep):
                raise ValueError(f"endpoint {ep!r} is not of the form 'tcp/HOST:PORT'")
        if self.mode is ZenohMode.CLIENT and not self.connect and not self.config_file:
            raise ValueError("a client needs at least one endpoint in `connect`")


class LogLevel(enum.Enum):
    DEBUG = "DEBUG"
    INFO = "INFO"
    WARNING = "WARNING"
    ERROR = "ERROR"


class LogSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    level: LogLevel = LogLevel.INFO
    repeat_interval_s: Annotated[float, msgspec.Meta(gt=0)] = 5.0  # one line per repeated warning


class ServiceConfig(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Top-level fields of every service's TOML; services subclass it with their own table."""

    vehicle: str = "ego"
    zenoh: ZenohSettings = msgspec.field(default_factory=ZenohSettings)
    log: LogSettings = msgspec.field(default_factory=LogSettings)

    def __post_init__(self) -> None:
        if not _VEHICLE.match(self.vehicle):
            raise ValueError(f"vehicle {self.vehicle!r} must be letters, digits, '_' or '-'")
