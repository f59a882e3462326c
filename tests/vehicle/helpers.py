"""What the gateway's tests share: the sample DBC and the shipped mapping, frames encoded
with cantools, a core fed at chosen times."""

from typing import Any, cast

import can
import msgspec

from aeb_radar_camera.common.config.loader import load_config, parse_config
from aeb_radar_camera.common.config.vehicle import GatewaySettings, VehicleConfig
from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.services.vehicle.core import VehicleCore
from aeb_radar_camera.services.vehicle.dbc import load_dbc
from tests.vehicle.drive import DBC

DB = load_dbc(str(DBC))
SHIPPED = load_config(DEPLOY / "vehicle.toml", VehicleConfig).gateway
MS = 1_000_000
WALL0 = 1_700_000_000_000_000_000      # any wall time: the core only carries it


def settings(**tables: object) -> GatewaySettings:
    """The shipped mapping with tables of [gateway] replaced (as TOML would give them)."""
    base = msgspec.to_builtins(SHIPPED)
    base.update(tables)
    return parse_config({"gateway": base}, VehicleConfig).gateway


def frame(name: str, **values: float) -> tuple[int, bytes]:
    """The DBC message `name` encoded with these physical values (the others 0)."""
    message = DB.get_message_by_name(name)
    full = {s.name: 0 for s in message.signals} | values
    return message.frame_id, message.encode(full)


class Fed:
    """A core and a clock: `send` frames at the current time, `advance` it, `poll`."""

    def __init__(self, gateway: GatewaySettings | None = None) -> None:
        self.core = VehicleCore(gateway or SHIPPED, DB)
        self.mono = 1_000 * MS

    def send(self, name: str, **values: float) -> None:
        arb, data = frame(name, **values)
        self.core.on_frame(arb, data, False, WALL0 + self.mono, self.mono)

    def all_signals(self, kph: float = 36.0, gear: int = 3) -> None:
        """One frame of every mapped message."""
        self.send("VehicleSpeed", VehicleSpeed=kph)
        self.send("YawRate", YawRate=2.5)
        self.send("SteeringWheel", SteeringWheelAngle=-12.5, SteeringWheelRate=4.0)
        self.send("Pedals", AcceleratorPedal=40.0, Kickdown=0)
        self.send("Brake", BrakePedalPressed=0, BrakePressure=0.0)
        self.send("Gear", GearLever=gear)

    def advance(self, ms: float) -> None:
        self.mono += int(ms * MS)

    def poll(self) -> list:
        return self.core.poll(self.mono, WALL0 + self.mono)


def decoded(msg: can.Message) -> dict[str, Any]:
    """cantools' own decoding of a frame of the sample DBC, physical values (numbers, no
    value names). Raises KeyError (an ID the DBC does not have) or cantools' DecodeError."""
    return cast(dict[str, Any], DB.decode_message(msg.arbitration_id, bytes(msg.data),
                                                  decode_choices=False))
