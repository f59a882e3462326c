"""`aeb radar --config FILE`: ARS408 radars on one CAN bus to tracks and status on Zenoh.

Exit codes: 0 stopped by a signal (also while waiting for the router) or a replay ended
with exit_at_end, 1 the Zenoh session could not be opened, 2 invalid configuration.
"""

import sys

import zenoh

from aeb_radar_camera.common import systemd
from aeb_radar_camera.common.bus import Bus, BusError, TypedPublisher
from aeb_radar_camera.common.config.radar import RadarConfig
from aeb_radar_camera.common.keys import EGO_MOTION, RADAR_CAN, RADAR_STATUS, RADAR_TRACKS
from aeb_radar_camera.common.log import kv, setup_logging
from aeb_radar_camera.common.messages.radar import RadarStatus, RadarTracks
from aeb_radar_camera.common.realtime import ThreadRealtime, apply_process
from aeb_radar_camera.common.service import (
    config_checked,
    load_service_config,
    service_argparser,
    stop_event_on_signals,
)
from aeb_radar_camera.common.systemd import Watchdog
from aeb_radar_camera.services.radar.ports import ConfigurationError, check_settings
from aeb_radar_camera.services.radar.shell import RadarShell


class ZenohRadarOutput:
    """Publishes through the key registry; declares one health token per radar."""

    def __init__(self, bus: Bus, sensors: list[str]) -> None:
        self._bus = bus
        self._sensors = sensors
        self._tracks: dict[str, TypedPublisher[RadarTracks]] = {
            s: bus.publisher(RADAR_TRACKS, sensor=s) for s in sensors}
        self._status: dict[str, TypedPublisher[RadarStatus]] = {
            s: bus.publisher(RADAR_STATUS, sensor=s) for s in sensors}
        self._tokens: list[zenoh.LivelinessToken] = []

    def tracks(self, sensor: str, msg: RadarTracks) -> None:
        self._tracks[sensor].put(msg)

    def status(self, sensor: str, msg: RadarStatus) -> None:
        self._status[sensor].put(msg)

    def serving(self) -> None:
        self._tokens = [self._bus.declare_health("radar", s) for s in self._sensors]
        systemd.ready(f"serving radar {','.join(self._sensors)}")


def main(argv: list[str] | None = None) -> int:
    args = service_argparser("radar", __doc__ or "").parse_args(argv)
    cfg = load_service_config(args, RadarConfig)
    log = setup_logging("radar", cfg.log.level.value)
    try:
        check_settings(cfg.radar.can, cfg.radar.replay)
    except ConfigurationError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.check:
        return config_checked("radar", args)
    stop = stop_event_on_signals()
    sensors = [s.name for s in cfg.radar.sensors]
    try:
        opened = Bus.open_until_stopped(cfg.zenoh, cfg.vehicle, "radar", stop, log)
    except BusError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    if opened is None:
        return 0
    bus = opened
    with bus:
        raw = cfg.radar.raw_can
        service = RadarShell(cfg.radar, ZenohRadarOutput(bus, sensors), watchdog=Watchdog(),
                             raw_can=(bus.publisher(RADAR_CAN, bus=raw.bus).put
                                      if raw.publish else None))
        if cfg.radar.ego_motion.forward:
            bus.subscribe(EGO_MOTION, lambda msg, key: service.on_ego_motion(msg))
        log.info(kv("radar_start", sensors=",".join(sensors),
                    interface=service.interface, channel=service.channel))
        apply_process(cfg.radar.realtime, log)
        ThreadRealtime(cfg.radar.realtime, log, "radar CAN loop").ensure()
        code = service.run(stop)
    log.info(kv("radar_stopped", code=code))
    return code


if __name__ == "__main__":
    sys.exit(main())
