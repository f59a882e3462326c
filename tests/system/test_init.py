"""`aeb init DIR`: an editable copy of deploy/ that works wherever it is written."""

from pathlib import Path

import pytest

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.config.camera import CameraConfig
from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import load_config
from aeb_radar_camera.common.config.radar import RadarConfig
from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.tools.init import UNIT_AEB, UNIT_CONFIGS, main
from aeb_radar_camera.tools.launch.table import load_table, resolve_launches


def shipped_files() -> set[str]:
    return {p.relative_to(DEPLOY).as_posix() for p in DEPLOY.rglob("*")
            if p.is_file() and "__pycache__" not in p.parts}


@pytest.fixture
def vehicle(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)          # paths must not depend on the current directory
    target = tmp_path / "car7"
    assert main([str(target)]) == 0
    assert f"wrote {len(shipped_files())} files" in capsys.readouterr().out
    return target


def test_the_copy_holds_every_shipped_file(vehicle):
    copied = {p.relative_to(vehicle).as_posix() for p in vehicle.rglob("*") if p.is_file()}
    assert copied == shipped_files()
    assert (vehicle / "recordings/ars408/LICENSE-Apache-2.0.txt").is_file()


def test_the_copys_configs_use_the_copys_own_files(vehicle):
    # a vehicle edits its copy: the calibration a config names is the copy's, not deploy/'s
    cam = load_config(vehicle / "camera.toml", CameraConfig)
    fusion = load_config(vehicle / "fusion.toml", FusionConfig)
    assert Path(cam.camera.calibration) == vehicle / "calibration/d435_848x480.toml"
    assert Path(fusion.fusion.calibration) == Path(cam.camera.calibration)
    Calibration.load(cam.camera.calibration)
    replay = load_config(vehicle / "radar-replay.toml", RadarConfig)
    assert Path(replay.radar.replay.file).is_relative_to(vehicle)


@pytest.mark.parametrize("table", ["single-host", "ecu-a", "ecu-b"])
def test_the_copys_tables_resolve_inside_the_copy(vehicle, table):
    path = vehicle / f"{table}.toml"
    t, workdir = load_table(path)
    assert workdir == vehicle
    for launch in resolve_launches(t, workdir, str(path)):
        for i, arg in enumerate(launch.argv):
            if arg in ("--config", "--config-file"):
                assert Path(launch.argv[i + 1]).is_relative_to(vehicle), launch


def test_the_copys_units_run_this_aeb_on_the_copy(vehicle):
    units = sorted((vehicle / "systemd").glob("*.service"))
    assert units
    for unit in units:
        text = unit.read_text()
        assert UNIT_AEB not in text and UNIT_CONFIGS + "/" not in text, unit.name
        assert str(vehicle) in text


def test_a_non_empty_folder_is_refused_unless_forced(vehicle, capsys):
    (vehicle / "brake.toml").write_text("# edited\n")
    assert main([str(vehicle)]) == 2
    assert "not empty" in capsys.readouterr().err
    assert (vehicle / "brake.toml").read_text() == "# edited\n"
    assert main([str(vehicle), "--force"]) == 0
    assert (vehicle / "brake.toml").read_text() == (DEPLOY / "brake.toml").read_text()
