"""`--set section.key=value` and the options that stand for one (`--port`, `--instance`,
`--calibration`, `--connect`, `--vehicle`, `--log-level`): set in the TOML's tables
before validation, typed by the setting, paths relative to the current directory, and a
clear error naming the key (exit 2) for a setting that does not exist or a bad value."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from aeb_radar_camera.common.config import ConfigError, load_config
from aeb_radar_camera.common.config.brake import BrakeConfig
from aeb_radar_camera.common.config.camera import CameraConfig, OpenCVSource
from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.overrides import OverrideError, parse_set
from aeb_radar_camera.common.resources import DEPLOY, EXAMPLE_CALIBRATION
from aeb_radar_camera.common.service import load_service_config, service_argparser
from aeb_radar_camera.services.brake.main import SHORTCUTS as BRAKE_SHORTCUTS
from aeb_radar_camera.services.fusion.main import SHORTCUTS as FUSION_SHORTCUTS


def fusion(tmp_path: Path, *sets: str, text: str = "[fusion]\ninstance = 'a'\n") -> FusionConfig:
    path = tmp_path / "fusion.toml"
    path.write_text(text)
    return load_config(path, FusionConfig, [parse_set(s) for s in sets])


def test_values_are_read_as_toml_and_typed_by_the_setting(tmp_path):
    cfg = fusion(tmp_path, "fusion.decision.hold_s=0.5", "fusion.frames.align=false",
                 "fusion.verifier.params.tau=0.03", "fusion.verifier.params.low=30",
                 "fusion.instance=42", "fusion.gate_scope=all", "vehicle=car_2")
    s = cfg.fusion
    assert s.decision.hold_s == 0.5 and s.frames.align is False
    assert s.verifier.params == {"tau": 0.03, "low": 30}
    assert s.instance == "42"                 # a name takes the text as written
    assert s.gate_scope.value == "all" and cfg.vehicle == "car_2"


def test_overrides_win_over_the_file_and_the_last_one_wins(tmp_path):
    cfg = fusion(tmp_path, "fusion.instance=b", "fusion.instance=c",
                 text="[fusion]\ninstance = 'a'\nstats_interval_s = 3.0\n")
    assert cfg.fusion.instance == "c" and cfg.fusion.stats_interval_s == 3.0


def test_a_path_on_the_command_line_is_relative_to_the_current_directory(tmp_path,
                                                                          monkeypatch):
    (tmp_path / "conf").mkdir()
    (tmp_path / "work").mkdir()
    monkeypatch.chdir(tmp_path / "work")
    path = tmp_path / "conf" / "fusion.toml"
    path.write_text("[fusion]\ncommand_key = 'keys/x.key'\n")
    cfg = load_config(path, FusionConfig, [parse_set("fusion.calibration=cal.toml"),
                                           parse_set("fusion.verifier.params.weights=w.npz")])
    assert cfg.fusion.calibration == str(tmp_path / "work" / "cal.toml")
    assert cfg.fusion.verifier.params["weights"] == str(tmp_path / "work" / "w.npz")
    assert cfg.fusion.command_key == str(tmp_path / "conf" / "keys" / "x.key")   # the file's


def test_a_tagged_table_takes_the_settings_of_its_kind(tmp_path):
    path = tmp_path / "camera.toml"
    path.write_text(f"[camera]\ncalibration = '{EXAMPLE_CALIBRATION}'\n"
                    "[camera.source]\nkind = 'opencv'\ndevice = '0'\n")
    cfg = load_config(path, CameraConfig, [parse_set("camera.source.device=1"),
                                           parse_set("camera.source.backend=v4l2")])
    source = cfg.camera.source
    assert isinstance(source, OpenCVSource) and (source.device, source.backend) == ("1", "v4l2")
    with pytest.raises(ConfigError, match=r"camera\.source has no setting 'bag'"):
        load_config(path, CameraConfig, [parse_set("camera.source.bag=x.bag")])


@pytest.mark.parametrize(("item", "named"), [
    ("fusion.instanc=x", "--set fusion.instanc=x: fusion has no setting 'instanc'"),
    ("fusoin.instance=x", "the configuration has no setting 'fusoin'"),
    ("fusion.decision.hold_s=-1", "$.fusion.decision.hold_s"),
    ("fusion.decision.hold_s=soon", "$.fusion.decision.hold_s"),
    ("fusion.frames.align.x=1", "fusion.frames.align is not a table of settings"),
    ("fusion.cameras.name=x", "fusion.cameras is not a table of settings"),
    ("fusion.instance=a/b", "instance 'a/b'"),
])
def test_a_bad_override_is_an_error_naming_the_key(tmp_path, item, named):
    with pytest.raises(ConfigError) as err:
        fusion(tmp_path, item)
    assert named in str(err.value)


@pytest.mark.parametrize("item", ["nodot", "=1", "fusion.=1", "fusion..x=1"])
def test_an_override_needs_a_name_and_a_value(item):
    with pytest.raises(OverrideError, match=r"expected SECTION\.KEY=VALUE"):
        parse_set(item)


def test_the_options_that_stand_for_a_setting(tmp_path):
    parser = service_argparser("brake", "", BRAKE_SHORTCUTS)
    args = parser.parse_args(["--port", "/dev/ttyUSB1", "--connect", "tcp/10.0.0.1:7447",
                              "--connect", "tcp/10.0.0.2:7447", "--vehicle", "car2",
                              "--log-level", "debug", "--set", "brake.serial.baudrate=9600"])
    cfg = load_service_config(args, BrakeConfig)
    assert (cfg.brake.serial.port, cfg.brake.serial.baudrate) == ("/dev/ttyUSB1", 9600)
    assert cfg.zenoh.connect == ("tcp/10.0.0.1:7447", "tcp/10.0.0.2:7447")
    assert (cfg.vehicle, cfg.log.level.value) == ("car2", "DEBUG")
    fusion_args = service_argparser("fusion", "", FUSION_SHORTCUTS).parse_args(
        ["--instance", "7", "--calibration", "c.toml"])
    s = load_service_config(fusion_args, FusionConfig).fusion
    assert (s.instance, s.calibration) == ("7", os.path.join(os.getcwd(), "c.toml"))


@pytest.mark.parametrize("service", ["radar", "camera", "fusion", "brake"])
def test_every_service_refuses_an_unknown_setting_at_check(service):
    proc = subprocess.run([sys.executable, "-m", f"aeb_radar_camera.services.{service}", "--check",
                           "--set", f"{service}.no_such_key=1"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert f"--set {service}.no_such_key=1: {service} has no setting 'no_such_key'" \
        in proc.stderr


def test_check_takes_a_valid_override_as_a_start_would():
    proc = subprocess.run([sys.executable, "-m", "aeb_radar_camera.services.fusion", "-c",
                           str(DEPLOY / "fusion.toml"), "--check", "--set",
                           "fusion.verifier.params.confirm_llr=2.0"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "fusion: configuration ok" in proc.stdout


def test_check_refuses_a_parameter_the_verifier_does_not_have():
    proc = subprocess.run([sys.executable, "-m", "aeb_radar_camera.services.fusion", "-c",
                           str(DEPLOY / "fusion.toml"), "--check", "--set",
                           "fusion.verifier.params.tau=0.03"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "invalid params: Object contains unknown field `tau`" in proc.stderr
