"""The brake service's configuration: the shipped example, and failing fast."""

import subprocess
import sys

import msgspec

from aeb_radar_camera.common.config.brake import BrakeConfig
from aeb_radar_camera.common.config.loader import load_config, parse_config
from tests.support import REPO


def test_shipped_example_is_valid_and_documents_the_defaults():
    shipped = load_config(REPO / "deploy/brake.toml", BrakeConfig)
    defaults = parse_config({}, BrakeConfig)
    # the deliberate differences: a vehicle runs the brake real-time (docs/deploy.md), and
    # the shipped file names the (insecure example) command key, which has no default
    assert shipped.brake.realtime.priority > 0
    assert shipped.brake.command_keys == (str(REPO / "deploy/keys/primary.key"),)
    assert defaults.brake.command_keys == ()
    as_default = msgspec.structs.replace(shipped.brake, realtime=defaults.brake.realtime,
                                         command_keys=())
    assert msgspec.structs.replace(shipped, brake=as_default) == defaults


def test_an_invalid_field_stops_the_service_at_start_naming_it(tmp_path):
    bad = tmp_path / "brake.toml"
    bad.write_text("[brake.actuator]\nheartbeat_ms = 200.0\nttl_ms = 250\n")
    res = subprocess.run([sys.executable, "-m", "aeb_radar_camera.services.brake", "--config",
                          str(bad)],
                         cwd=REPO, capture_output=True, text=True, timeout=60)
    assert res.returncode == 2
    assert "ttl_ms must be at least two heartbeats" in res.stderr
    assert "brake.actuator" in res.stderr
