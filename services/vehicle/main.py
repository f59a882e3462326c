"""`aeb vehicle --config FILE`: the car's CAN decoded through its DBC to the vehicle's
state on Zenoh (`vehicle/motion`, `vehicle/driver`) and the gateway's status.

Exit codes: 0 stopped by a signal (also while waiting for the router) or a replay ended
with exit_at_end, 1 the Zenoh session could not be opened, 2 invalid configuration (a
setting, the DBC file, or a signal the DBC does not have).
"""

import sys

import zenoh

from aeb_radar_camera.common import systemd
from aeb_radar_camera.common.bus import Bus, BusError, TypedPublisher
from aeb_radar_camera.common.can_port import ConfigurationError, check_settings
from aeb_radar_camera.common.config.vehicle import GatewaySettings, VehicleConfig
from aeb_radar_camera.common.keys import EGO_MOTION, VEHICLE_DRIVER, VEHICLE_STATUS
from aeb_radar_camera.common.log import kv, setup_logging
from aeb_radar_camera.common.messages.vehicle import DriverInputs, EgoMotion, VehicleStatus
from aeb_radar_camera.common.service import (
    config_checked,
    load_service_config,
    service_argparser,
    stop_event_on_signals,
)
from aeb_radar_camera.common.systemd import Watchdog
from aeb_radar_camera.services.vehicle.core import VehicleCore
from aeb_radar_camera.services.vehicle.dbc import load_dbc
from aeb_radar_camera.services.vehicle.mapping import MappingError
from aeb_radar_camera.services.vehicle.shell import SERVICE, VehicleShell

TABLE = "gateway"


class ZenohVehicleOutput:
    """Publishes through the key registry; declares the gateway's health token."""

    def __init__(self, bus: Bus, gateway: str) -> None:
        self._bus = bus
        self._gateway = gateway
        self._motion: TypedPublisher[EgoMotion] = bus.publisher(EGO_MOTION)
        self._driver: TypedPublisher[DriverInputs] = bus.publisher(VEHICLE_DRIVER)
        self._status: TypedPublisher[VehicleStatus] = bus.publisher(VEHICLE_STATUS,
                                                                    gateway=gateway)
        self._token: zenoh.LivelinessToken | None = None

    def motion(self, msg: EgoMotion) -> None:
        self._motion.put(msg)

    def driver(self, msg: DriverInputs) -> None:
        self._driver.put(msg)

    def status(self, msg: VehicleStatus) -> None:
        self._status.put(msg)

    def serving(self) -> None:
        self._token = self._bus.declare_health(SERVICE, self._gateway)
        systemd.ready(f"serving vehicle gateway {self._gateway}")


def build_core(settings: GatewaySettings) -> VehicleCore:
    """The core of `settings`: its DBC read, its mapping checked against it, its CAN
    settings checked. Raises ConfigurationError or MappingError (exit code 2)."""
    check_settings(settings.can, settings.replay, TABLE)
    return VehicleCore(settings, load_dbc(settings.dbc))


def main(argv: list[str] | None = None) -> int:
    args = service_argparser(SERVICE, __doc__ or "").parse_args(argv)
    cfg = load_service_config(args, VehicleConfig)
    log = setup_logging(SERVICE, cfg.log.level.value)
    try:
        core = build_core(cfg.gateway)
    except (ConfigurationError, MappingError) as exc:
        print(f"error: {args.config or '<defaults>'}: {exc}", file=sys.stderr)
        return 2
    if args.check:
        return config_checked(SERVICE, args)
    stop = stop_event_on_signals()
    try:
        opened = Bus.open_until_stopped(cfg.zenoh, cfg.vehicle, SERVICE, stop, log)
    except BusError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    if opened is None:
        return 0
    with opened as bus:
        service = VehicleShell(cfg.gateway, core, ZenohVehicleOutput(bus, cfg.gateway.name),
                               watchdog=Watchdog())
        log.info(kv("vehicle_start", gateway=cfg.gateway.name, dbc=service.dbc,
                    interface=service.link.interface, channel=service.link.channel,
                    messages=",".join(m.key for m in core.plan.messages)))
        code = service.run(stop)
    log.info(kv("vehicle_stopped", code=code))
    return code


if __name__ == "__main__":
    sys.exit(main())
