"""`aeb camera` fails fast, with exit code 2 and a message naming the problem, on bad
configuration; the shipped configs are valid."""

import signal
import sys

import pytest

from aeb_radar_camera.common.config.camera import (
    CameraConfig,
    FolderSource,
    RealSenseSource,
    SyntheticSource,
)
from aeb_radar_camera.common.config.loader import load_config
from aeb_radar_camera.services.camera.main import main
from aeb_radar_camera.services.camera.registry import check_source
from tests.camera.helpers import CALIBRATION


@pytest.fixture(autouse=True)
def keep_signal_handlers():
    """main() installs SIGINT/SIGTERM handlers: give pytest its own back."""
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    yield
    for s, handler in saved.items():
        signal.signal(s, handler)


def run_main(tmp_path, body: str, capsys) -> tuple[int, str]:
    cfg = tmp_path / "camera.toml"
    # An endpoint nobody listens on: a config error must be reported before connecting.
    cfg.write_text('[zenoh]\nconnect = ["tcp/127.0.0.1:9"]\n' + body)
    with pytest.raises(SystemExit) as exit_info:
        sys.exit(main(["-c", str(cfg)]))
    return int(exit_info.value.code or 0), capsys.readouterr().err


@pytest.mark.parametrize(
    ("body", "says"),
    [
        ('[camera]\ncalibration = "nope.toml"\n', "nope.toml: cannot read calibration"),
        (f'[camera]\ncalibration = "{CALIBRATION}"\nfps = 0\n', "$.camera.fps"),
        (f'[camera]\ncalibration = "{CALIBRATION}"\nframerate = 30\n', "framerate"),
        (f'[camera]\ncalibration = "{CALIBRATION}"\n[camera.source]\nkind = "webcam"\n',
         "$.camera.source.kind"),
        (f'[camera]\ncalibration = "{CALIBRATION}"\n[camera.source]\nkind = "synthetic"\n'
         'factory = "aeb_radar_camera.tools.nothing_here:make"\n',
         "cannot import module 'aeb_radar_camera.tools.nothing_here'"),
        # a factory named by the repository's folder alone: told the installed name
        (f'[camera]\ncalibration = "{CALIBRATION}"\n[camera.source]\nkind = "synthetic"\n'
         'factory = "tools.nothing_here:make"\n', "'aeb_radar_camera.tools.nothing_here:make'"),
    ],
)
def test_bad_configuration_exits_2_naming_the_problem(tmp_path, capsys, body, says):
    code, err = run_main(tmp_path, body, capsys)
    assert code == 2
    assert says in err


def test_realsense_without_its_extra_exits_2_with_the_install_command(tmp_path, capsys,
                                                                       monkeypatch):
    monkeypatch.setitem(sys.modules, "pyrealsense2", None)
    code, err = run_main(tmp_path, f'[camera]\ncalibration = "{CALIBRATION}"\n', capsys)
    assert code == 2
    assert "pip install 'aeb-radar-camera[realsense]'" in err


def test_shipped_configs_are_valid():
    real = load_config("deploy/camera.toml", CameraConfig)
    assert isinstance(real.camera.source, RealSenseSource)
    assert (real.camera.source.width, real.camera.source.height, real.camera.source.fps) == (
        848, 480, 30)
    sim = load_config("deploy/camera-sim.toml", CameraConfig)
    assert isinstance(sim.camera.source, SyntheticSource)
    check_source(sim.camera)   # the factory imports
    folder = load_config("deploy/camera-folder.toml", CameraConfig)
    assert isinstance(folder.camera.source, FolderSource)
    assert folder.camera.calibration == CALIBRATION
