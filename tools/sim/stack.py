"""The stack under simulation: the service configurations that point the real services
at the simulated sensors and actuator, written into a run folder.

- radar: python-can `slcan` on the simulated radar's pty (or `socketcan` on a vcan), as
  with a USB-CAN adapter;
- camera: the synthetic-source plugin `tools.sim.camera_source:make_source` (renders
  `sim/world`), with the example D435 calibration that fusion also uses;
- fusion: deploy/fusion.toml (the shipped `primary`), its real-time priority set to the
  stack's (off unless asked);
- brake: deploy defaults, with the serial port on the simulated actuator's pty.
"""

import json
from dataclasses import dataclass
from pathlib import Path

from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import load_config, relocated_text
from aeb_radar_camera.common.resources import DEPLOY, EXAMPLE_CALIBRATION, EXAMPLE_KEYS
from aeb_radar_camera.tools.sim.radar_reach import radar_for

CALIBRATION = EXAMPLE_CALIBRATION
FUSION_CONFIG = DEPLOY / "fusion.toml"
SERVICES = ("radar", "camera", "fusion", "brake")
# service -> its liveliness token (service, instance)
TOKENS = {"radar": ("radar", "front"), "camera": ("camera", "front"),
          "fusion": ("fusion", "primary"), "brake": ("brake", "main")}


@dataclass(frozen=True)
class StackConfigs:
    radar: Path
    camera: Path
    fusion: Path
    brake: Path

    def of(self, service: str) -> Path:
        return {"radar": self.radar, "camera": self.camera, "fusion": self.fusion,
                "brake": self.brake}[service]


def _toml_list(values: list[str]) -> str:
    return json.dumps(values)


def write_configs(folder: Path, endpoint: str, actuator_port: str, can_channel: str,
                  can_interface: str = "slcan", camera_fps: float = 30.0,
                  fusion_config: Path = FUSION_CONFIG,
                  heartbeat_ms: float | None = None,
                  realtime_priority: int = 0, raw_can: bool = False,
                  fusion_instance: str = "primary") -> StackConfigs:
    """Write radar, camera, fusion and brake TOMLs into `folder`; fusion's is the shipped
    one with `[fusion.realtime]` set (its endpoint comes from `--connect`). Returns every
    config's path.

    `heartbeat_ms` overrides the brake's actuator heartbeat: above one radar cycle, every
    line on the actuator while commands flow is a command line (one per radar cycle),
    which lets a test pair cycles and lines exactly (tools/sim/latency.py).
    `realtime_priority` > 0: SCHED_FIFO for the latency path of radar, fusion and brake
    (`[*.realtime]`, the brake's timer), as on a vehicle. `raw_can`: the radar publishes
    its raw CAN frames (`[radar.raw_can]`), for recordings that re-run the radar.
    `fusion_instance`: the instance the brake follows (the one `fusion_config` names)."""
    rt = f"\n[{{}}.realtime]\npriority = {realtime_priority}\n" if realtime_priority else ""
    folder.mkdir(parents=True, exist_ok=True)
    zenoh = f"[zenoh]\nconnect = {_toml_list([endpoint])}\n"
    options = "{ sleep_after_open = 0 }" if can_interface == "slcan" else "{}"
    bitrate = 500_000 if can_interface == "slcan" else 0
    reach_m = radar_for(load_config(fusion_config, FusionConfig)).prefilter.max_range_m
    radar = folder / "radar.toml"
    radar.write_text(
        "# SIMULATION: the radar service on the simulated ARS408's CAN link.\n"
        f'vehicle = "ego"\n{zenoh}\n[radar.can]\ninterface = "{can_interface}"\n'
        f'channel = "{can_channel}"\nbitrate = {bitrate}\noptions = {options}\n\n'
        '[[radar.sensors]]\nname = "front"\nsensor_id = 0\n'
        # the simulator publishes vehicle/motion: the radar forwards it as 0x300 / 0x301
        '\n[radar.ego_motion]\nforward = true\n'
        # out to the fusion rule's range gate, as deploy/radar.toml for deploy/fusion.toml
        + f'\n[radar.prefilter]\nmax_range_m = {reach_m}\n' + rt.format("radar")
        + ("\n[radar.raw_can]\npublish = true\n" if raw_can else ""))
    camera = folder / "camera.toml"
    camera.write_text(
        "# SIMULATION: the camera service rendering the simulated world (synthetic plugin).\n"
        f'vehicle = "ego"\n{zenoh}\n[camera]\nname = "front"\n'
        f'calibration = "{CALIBRATION}"\nfps = {camera_fps}\njpeg_quality = 80\n\n'
        '[camera.source]\nkind = "synthetic"\n'
        'factory = "aeb_radar_camera.tools.sim.camera_source:make_source"\n')
    brake = folder / "brake.toml"
    brake.write_text(
        "# The brake service on the simulated actuator's pty (a SIMULATION of the actuator).\n"
        f'vehicle = "ego"\n{zenoh}\n[brake]\ninstance = "{fusion_instance}"\n'
        f'command_keys = ["{EXAMPLE_KEYS / (fusion_instance + ".key")}"]'
        '   # INSECURE EXAMPLE KEY\n'
        + f'\n[brake.serial]\nport = "{actuator_port}"\n'
        + ("" if heartbeat_ms is None else
           f"\n[brake.actuator]\nheartbeat_ms = {heartbeat_ms}\nttl_ms = "
           f"{max(250, int(2 * heartbeat_ms) + 10)}\n")
        + rt.format("brake"))
    fusion = folder / "fusion.toml"
    # the shipped file's relative paths (its calibration) made absolute for the copy
    fusion.write_text(with_realtime(relocated_text(fusion_config, FusionConfig), "fusion",
                                    realtime_priority))
    return StackConfigs(radar, camera, fusion, brake)


def fusion_instance(fusion_config: Path) -> str:
    """The instance a fusion config names. Raises ConfigError for a bad file."""
    return load_config(fusion_config, FusionConfig).fusion.instance


def with_realtime(toml_text: str, table: str, priority: int) -> str:
    """A service config with its `[<table>.realtime]` replaced by one at `priority` (0:
    normal scheduling), whatever the shipped file says."""
    header = f"[{table}.realtime]"
    kept: list[str] = []
    skipping = False
    for line in toml_text.splitlines():
        stripped = line.strip()
        if stripped.startswith("["):
            skipping = stripped.split("#", 1)[0].strip() == header
        if not skipping:
            kept.append(line)
    return "\n".join(kept).rstrip("\n") + f"\n\n{header}\npriority = {priority}\n"
