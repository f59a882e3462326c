"""Relative paths inside a config file resolve against the file's folder, whatever the
current directory: every path field of every service's config, at any depth."""

import subprocess
import sys
from pathlib import Path

import pytest

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.config.camera import (
    CameraConfig,
    FolderSource,
    OpenCVSource,
    RealSenseSource,
)
from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import ConfigError, load_config, parse_config
from aeb_radar_camera.common.config.radar import RadarConfig
from aeb_radar_camera.common.resources import DEPLOY, EXAMPLE_CALIBRATION


@pytest.fixture
def elsewhere(tmp_path, monkeypatch):
    """The current directory is somewhere that holds none of the files."""
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    return cwd


def test_a_shipped_camera_config_finds_its_calibration_from_another_directory(elsewhere):
    cfg = load_config(DEPLOY / "camera-sim.toml", CameraConfig)
    assert Path(cfg.camera.calibration) == EXAMPLE_CALIBRATION
    Calibration.load(cfg.camera.calibration)


def test_the_shipped_replay_config_finds_the_bundled_recording(elsewhere):
    cfg = load_config(DEPLOY / "radar-replay.toml", RadarConfig)
    assert Path(cfg.radar.replay.file).is_file()


def test_nested_paths_resolve_against_the_files_folder(tmp_path, elsewhere):
    vehicle = tmp_path / "vehicle"
    vehicle.mkdir()
    (vehicle / "fusion.toml").write_text(
        '[zenoh]\nconfig_file = "zenoh/client.json5"\n'
        '[[fusion.cameras]]\nname = "left"\ncalibration = "cal/left.toml"\n'
        '[[fusion.cameras]]\nname = "right"\ncalibration = "/abs/right.toml"\n')
    f = load_config(vehicle / "fusion.toml", FusionConfig)
    assert f.zenoh.config_file == str(vehicle / "zenoh/client.json5")
    assert [c.calibration for c in f.fusion.cameras] == [str(vehicle / "cal/left.toml"),
                                                         "/abs/right.toml"]


@pytest.mark.parametrize(("source", "expected"), [
    ('kind = "folder"\npath = "frames"', lambda d: str(d / "frames")),
    ('kind = "folder"\npath = "../frames"', lambda d: str(d.parent / "frames")),
    ('kind = "opencv"\ndevice = "drive.mp4"', lambda d: str(d / "drive.mp4")),
    ('kind = "opencv"\ndevice = "0"', lambda d: "0"),                       # a V4L2 index
    ('kind = "opencv"\ndevice = "rtsp://cam/stream"', lambda d: "rtsp://cam/stream"),
    ('kind = "opencv"\ndevice = "/dev/video2"', lambda d: "/dev/video2"),
    ('kind = "realsense"\nbag = "drive.bag"', lambda d: str(d / "drive.bag")),
    ('kind = "realsense"', lambda d: ""),                                    # empty stays
])
def test_camera_source_paths(tmp_path, elsewhere, source, expected):
    (tmp_path / "camera.toml").write_text(
        f'[camera]\ncalibration = "cal.toml"\n[camera.source]\n{source}\n')
    cfg = load_config(tmp_path / "camera.toml", CameraConfig)
    assert cfg.camera.calibration == str(tmp_path / "cal.toml")
    src = cfg.camera.source
    value = {FolderSource: "path", OpenCVSource: "device", RealSenseSource: "bag"}[type(src)]
    assert getattr(src, value) == expected(tmp_path)


def test_home_is_expanded(tmp_path, elsewhere, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))
    (tmp_path / "radar.toml").write_text(
        '[radar.can]\ninterface = "replay"\n[radar.replay]\nfile = "~/drive.log"\n')
    assert load_config(tmp_path / "radar.toml", RadarConfig).radar.replay.file == \
        str(tmp_path / "drive.log")


def test_a_config_built_from_a_mapping_keeps_paths_as_given():
    cfg = parse_config({"camera": {"calibration": "cal.toml"}}, CameraConfig)
    assert cfg.camera.calibration == "cal.toml"


def test_fusions_default_calibration_is_the_shipped_example_from_anywhere(elsewhere):
    assert Path(parse_config({}, FusionConfig).fusion.calibration) == EXAMPLE_CALIBRATION
    assert EXAMPLE_CALIBRATION.is_file()


def test_a_relocated_copy_of_a_config_keeps_pointing_at_the_same_files(tmp_path):
    from aeb_radar_camera.common.config.loader import relocated_text

    original = load_config(DEPLOY / "fusion.toml", FusionConfig)
    (tmp_path / "fusion.toml").write_text(relocated_text(DEPLOY / "fusion.toml", FusionConfig))
    assert load_config(tmp_path / "fusion.toml", FusionConfig) == original
    # a naive copy would not: the calibration would be looked for beside the copy
    (tmp_path / "naive.toml").write_text((DEPLOY / "fusion.toml").read_text())
    assert load_config(tmp_path / "naive.toml", FusionConfig).fusion.calibration == \
        str(tmp_path / "calibration/d435_848x480.toml")


def test_a_verifiers_weights_file_resolves_against_the_files_folder(tmp_path, elsewhere):
    vehicle = tmp_path / "vehicle"
    vehicle.mkdir()
    (vehicle / "fusion.toml").write_text(
        '[fusion.verifier]\nname = "combined"\n'
        'params = { weights = "verifiers/w.json", tau = 1.5, appearance = "hog_linear" }\n')
    params = load_config(vehicle / "fusion.toml", FusionConfig).fusion.verifier.params
    assert params == {"weights": str(vehicle / "verifiers" / "w.json"), "tau": 1.5,
                      "appearance": "hog_linear"}
    # Other parameters that happen to be strings stay as written.
    assert params["appearance"] == "hog_linear"


def test_a_nul_byte_in_any_setting_is_a_config_error_naming_the_field(tmp_path):
    (tmp_path / "fusion.toml").write_text(
        '[fusion.verifier]\nname = "combined"\n'
        'params = { weights = "verifiers/w\\u0000.json", appearance = "hog_linear" }\n')
    with pytest.raises(ConfigError, match=r"\$\.fusion\.verifier\.params\.weights holds a NUL"):
        load_config(tmp_path / "fusion.toml", FusionConfig)


def test_the_fusion_service_exits_2_on_a_nul_byte_in_its_weights_path(tmp_path):
    # exit 2 is "configuration rejected": `aeb up` and systemd do not restart it
    (tmp_path / "fusion.toml").write_text(
        '[fusion.verifier]\nname = "combined"\n'
        'params = { weights = "verifiers/w\\u0000.json", appearance = "hog_linear" }\n')
    for argv in (["--check"], []):
        run = subprocess.run([sys.executable, "-m", "aeb_radar_camera.services.fusion.main", "-c",
                              str(tmp_path / "fusion.toml"), *argv],
                             capture_output=True, text=True, timeout=120)
        assert run.returncode == 2, run.stderr
        assert "NUL byte" in run.stderr and "Traceback" not in run.stderr
