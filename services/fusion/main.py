"""`aeb fusion`: verify radar tracks in the camera image and decide NONE / WARNING / BRAKE.

    aeb fusion --config deploy/fusion.toml
    aeb fusion --config deploy/fusion-candidate.toml     # a shadow A/B instance
    aeb fusion --config deploy/fusion.toml --set fusion.verifier.params.tau=0.03

Exit codes: 0 after SIGINT/SIGTERM, 2 for an invalid configuration or calibration
(named on stderr), 1 when the bus cannot be opened.
"""

import logging
import sys

from aeb_radar_camera.common.bus import Bus, BusError
from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.command_auth import CommandSigner, KeyFileError, load_signing_key
from aeb_radar_camera.common.config.fusion import FusionConfig, FusionSettings
from aeb_radar_camera.common.config.loader import ConfigError
from aeb_radar_camera.common.log import kv, setup_logging
from aeb_radar_camera.common.realtime import apply_process
from aeb_radar_camera.common.service import (
    config_checked,
    load_service_config,
    service_argparser,
    stop_event_on_signals,
)
from aeb_radar_camera.common.systemd import Watchdog
from aeb_radar_camera.services.fusion.core import FusionCore
from aeb_radar_camera.services.fusion.frames import FrameDecoder
from aeb_radar_camera.services.fusion.roi import ColumnGeometry, ColumnProjector
from aeb_radar_camera.services.fusion.shell import FusionShell
from aeb_radar_camera.services.fusion.verifiers import VerifierConfigError, create

SHORTCUTS = {"--instance": ("fusion.instance", "instance name"),
             "--calibration": ("fusion.calibration", "calibration TOML of the one camera")}


def build_core(cfg: FusionConfig) -> tuple[FusionCore, dict[str, Calibration]]:
    """The core of a configured instance and each camera's calibration, by camera name.
    Raises ConfigError or VerifierConfigError."""
    s = cfg.fusion
    cals = {c.name: Calibration.load(c.calibration) for c in s.camera_inputs}
    verifier = create(s.verifier.name, s.verifier.params)
    geometry = ColumnGeometry(s.roi.column_height_m, s.roi.column_half_width_m,
                              s.roi.padding_px)
    projectors = {name: ColumnProjector(cal, geometry) for name, cal in cals.items()}
    return FusionCore(s, projectors, verifier), cals


def build_signer(s: FusionSettings, log: logging.Logger) -> CommandSigner | None:
    """The signer of this instance's commands; None without `command_key` (unsigned, which
    no brake follows: logged). Raises KeyFileError."""
    if not s.command_key:
        log.warning(kv("commands_unsigned", instance=s.instance,
                       note="no fusion.command_key: no brake follows these commands"))
        return None
    key = load_signing_key(s.command_key, s.instance)
    if key.insecure_example:
        log.warning(kv("insecure_example_key", key_id=key.key_id, path=key.path,
                       note="published with the source: demo and simulator only"))
    return CommandSigner(key)


def main(argv: list[str] | None = None) -> int:
    args = service_argparser("fusion", __doc__ or "", SHORTCUTS).parse_args(argv)
    cfg = load_service_config(args, FusionConfig)
    s = cfg.fusion
    log = setup_logging(f"fusion.{s.instance}", cfg.log.level.value)
    try:
        core, cals = build_core(cfg)
        signer = build_signer(s, log)
    except (ConfigError, VerifierConfigError, KeyFileError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for name, cal in cals.items():
        for warning in cal.warnings():
            log.warning(kv("calibration_implausible", camera=name, file=cal.origin,
                           detail=warning))
    if args.check:
        return config_checked("fusion", args)
    stop = stop_event_on_signals()
    try:
        opened = Bus.open_until_stopped(cfg.zenoh, cfg.vehicle, core.source, stop, log)
    except BusError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    if opened is None:
        log.info(kv("fusion_stopped"))
        return 0
    with opened as bus:
        decoders = [FrameDecoder(cal.width, cal.height, log, name) for name, cal in cals.items()]
        shell = FusionShell(bus, s, core, decoders, log, cals, signer)
        shell.start()
        apply_process(s.realtime, log)
        log.info(kv("fusion_ready", instance=s.instance, verifier=core.verifier.name,
                    params=core.verifier_params, radar=s.radar_sensor, cameras=core.camera_names,
                    calibration=",".join(c.calibration for c in s.camera_inputs)))
        code = shell.run(stop, Watchdog())
    log.info(kv("fusion_stopped", code=code))
    return code


if __name__ == "__main__":
    sys.exit(main())
