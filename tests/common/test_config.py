import subprocess
import sys

import pytest

from aeb_radar_camera.common.config import ConfigError, ServiceConfig, ZenohMode, load_config
from aeb_radar_camera.common.config.loader import parse_config


def write(tmp_path, text):
    p = tmp_path / "svc.toml"
    p.write_text(text)
    return p


def test_defaults_are_a_loopback_client_without_multicast():
    cfg = parse_config({}, ServiceConfig)
    assert cfg.vehicle == "ego"
    assert cfg.zenoh.mode is ZenohMode.CLIENT
    assert cfg.zenoh.connect == ("tcp/127.0.0.1:7447",)
    assert cfg.zenoh.multicast_scouting is False


def test_valid_file_loads(tmp_path):
    text = 'vehicle = "car2"\n[zenoh]\nconnect = ["tcp/10.0.0.1:7447"]\n'
    cfg = load_config(write(tmp_path, text), ServiceConfig)
    assert cfg.vehicle == "car2"
    assert cfg.zenoh.connect == ("tcp/10.0.0.1:7447",)


@pytest.mark.parametrize(
    ("text", "named"),
    [
        ("vehicel = 'x'\n", "vehicel"),
        ("[zenoh]\nmode = 'satellite'\n", "$.zenoh.mode"),
        ("[zenoh]\nconnect = ['10.0.0.1:7447']\n", "tcp/HOST:PORT"),
        ("[log]\nrepeat_interval_s = -1.0\n", "$.log.repeat_interval_s"),
        ("vehicle = 'a/b'\n", "vehicle"),
        ("[zenoh\n", "not valid TOML"),
    ],
)
def test_invalid_config_names_the_field(tmp_path, text, named):
    with pytest.raises(ConfigError) as err:
        load_config(write(tmp_path, text), ServiceConfig)
    assert named in str(err.value)
    assert "svc.toml" in str(err.value)


def test_missing_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "nope.toml", ServiceConfig)


def test_router_with_bad_endpoint_exits_non_zero():
    proc = subprocess.run([sys.executable, "-m", "aeb_radar_camera.common.router", "--listen",
                           "nonsense"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert "error:" in proc.stderr
