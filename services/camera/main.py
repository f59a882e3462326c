"""`aeb camera`: frames from the configured source to JPEG on Zenoh, plus CameraInfo."""

import sys

from aeb_radar_camera.common.bus import Bus, BusError
from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.config.camera import CameraConfig
from aeb_radar_camera.common.config.loader import ConfigError
from aeb_radar_camera.common.log import kv, setup_logging
from aeb_radar_camera.common.service import (
    config_checked,
    load_service_config,
    service_argparser,
    stop_event_on_signals,
)
from aeb_radar_camera.common.systemd import Watchdog
from aeb_radar_camera.services.camera.registry import build_source, check_source
from aeb_radar_camera.services.camera.shell import EXIT_CONFIG, CameraShell
from aeb_radar_camera.services.camera.source import SourceConfigError


def main(argv: list[str] | None = None) -> int:
    args = service_argparser("camera", __doc__ or "").parse_args(argv)
    cfg = load_service_config(args, CameraConfig)
    settings = cfg.camera
    log = setup_logging("camera", cfg.log.level.value)
    stop = stop_event_on_signals()
    try:
        cal = Calibration.load(settings.calibration)
        check_source(settings)
    except (ConfigError, SourceConfigError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_CONFIG
    for warning in cal.warnings():
        log.warning(kv("calibration_implausible", file=settings.calibration, detail=warning))
    if args.check:
        return config_checked("camera", args)
    try:
        opened = Bus.open_until_stopped(cfg.zenoh, cfg.vehicle, f"camera/{settings.name}",
                                        stop, log)
        if opened is None:
            log.info(kv("camera_stopped", code=0))
            return 0
        with opened as bus:
            try:
                source = build_source(settings, cal, bus)
            except SourceConfigError as exc:
                print(f"error: camera.source: {exc}", file=sys.stderr)
                return EXIT_CONFIG
            shell = CameraShell(settings, cal, source, bus, Watchdog())
            code = shell.run(stop)
            if shell.pipeline.fatal is not None:
                print(f"error: camera.source: {shell.pipeline.fatal}", file=sys.stderr)
    except BusError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_CONFIG
    log.info(kv("camera_stopped", code=code))
    return code


if __name__ == "__main__":
    sys.exit(main())
