"""The published example keys never move a real actuator without a loud opt-in: the
brake service, as its own process, refuses to start on one when its serial port is not
the simulator's pty (exit 2, the key and the port named); with `allow_example_key` it
starts and says so with a WARNING; on the simulated actuator the demo's key is taken."""

import os
import pty
from pathlib import Path

import pytest

from aeb_radar_camera.common.command_auth import CommandKey, load_key, new_key, write_key
from aeb_radar_camera.common.resources import EXAMPLE_KEYS
from aeb_radar_camera.services.brake.serial_link import simulated_port
from tests.support import ServiceProcess, python_module, wait_for

pytestmark = pytest.mark.slow

# a /dev path that is not there: what a real actuator's port looks like before it is
# plugged in (treated as real hardware)
REAL_PORT = "/dev/ttyACM-aeb-test-absent"


def relabelled_example(folder: Path) -> Path:
    """The shipped primary key copied under another id without its `insecure_example`
    flag, mode 0600: still the published secret."""
    shipped = load_key(EXAMPLE_KEYS / "primary.key")
    path = folder / "primary.key"
    write_key(path, CommandKey("primary-mine", "primary", shipped.secret))
    return path


def brake(folder: Path, key: Path, port: str, extra: str = "") -> ServiceProcess:
    config = folder / "brake.toml"
    config.write_text(f'[zenoh]\nconnect = ["tcp/127.0.0.1:1"]\n[brake]\n'
                      f'command_keys = ["{key}"]\n{extra}[brake.serial]\nport = "{port}"\n')
    return ServiceProcess("brake", python_module("aeb_radar_camera.services.brake", "--config",
                                                 str(config)),
                          folder)


@pytest.mark.parametrize("key", ["shipped", "relabelled"])
def test_the_brake_refuses_an_example_key_on_a_real_actuator(tmp_path: Path, key: str):
    path = EXAMPLE_KEYS / "primary.key" if key == "shipped" else relabelled_example(tmp_path)
    proc = brake(tmp_path, path, REAL_PORT)
    wait_for(lambda: not proc.alive(), 60, what="the brake to exit")
    out = proc.output()
    assert proc.proc.returncode == 2, out
    assert "INSECURE EXAMPLE KEY" in out and REAL_PORT in out and str(path) in out
    assert "allow_example_key" in out and "Traceback" not in out


def test_the_opt_in_starts_the_brake_with_a_warning(tmp_path: Path):
    proc = brake(tmp_path, relabelled_example(tmp_path), REAL_PORT,
                 "allow_example_key = true\n")
    try:
        wait_for(lambda: "insecure_example_key_accepted" in proc.output(), 60,
                 what="the warning")
        out = proc.output()
        assert "WARNING" in out and "REAL actuator" in out and proc.alive()
    finally:
        proc.stop()


def test_the_simulated_actuators_pty_takes_the_example_key(tmp_path: Path):
    master, slave = pty.openpty()
    try:
        link = tmp_path / "actuator"
        link.symlink_to(os.ttyname(slave))
        assert simulated_port(str(link)) and not simulated_port(REAL_PORT)
        assert simulated_port(str(tmp_path / "not-yet"))      # a simulator's link to come
        proc = brake(tmp_path, EXAMPLE_KEYS / "primary.key", str(link))
        try:
            wait_for(lambda: "insecure_example_key" in proc.output(), 60, what="start")
            assert proc.alive(), proc.output()
        finally:
            proc.stop()
    finally:
        os.close(master)
        os.close(slave)


def test_a_key_file_readable_by_others_stops_the_brake_naming_file_and_mode(tmp_path: Path):
    path = tmp_path / "own.key"
    write_key(path, new_key("primary"))
    path.chmod(0o640)
    proc = brake(tmp_path, path, REAL_PORT)
    wait_for(lambda: not proc.alive(), 60, what="the brake to exit")
    assert proc.proc.returncode == 2
    assert f"{path}: mode 0640" in proc.output()
