"""Every process a unit runs speaks sd_notify itself: READY=1 once it serves and WATCHDOG=1
from its own loop, sent from the unit's main process (the pid systemd started, so
NotifyAccess=main accepts it) - through `aeb up --exec` as the units start them, and
never from the children of `aeb up`. The test plays systemd's end of $NOTIFY_SOCKET."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from aeb_radar_camera.common.resources import DEPLOY, EXAMPLE_CALIBRATION, EXAMPLE_KEYS
from tests.notify_support import NotifyListener
from tests.support import START_TIMEOUT_S, free_port

pytestmark = pytest.mark.slow

WATCHDOG_USEC = "1000000"          # 1 s: pings at least every 0.5 s


def start(argv: list[str], listener: NotifyListener, log: Path) -> subprocess.Popen[bytes]:
    env = {**os.environ, **listener.env, "WATCHDOG_USEC": WATCHDOG_USEC,
           "PYTHONUNBUFFERED": "1"}
    env.pop("WATCHDOG_PID", None)
    return subprocess.Popen(argv, env=env, stdout=log.open("wb"), stderr=subprocess.STDOUT,
                            start_new_session=True)


def stop(proc: subprocess.Popen[bytes]) -> int:
    proc.terminate()
    try:
        return proc.wait(30)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait(5)


def ready_then_pings(listener: NotifyListener, proc: subprocess.Popen[bytes],
                     log: Path) -> str:
    """The READY=1 datagram, once two WATCHDOG=1 followed it; asserts every datagram came
    from the process itself."""
    try:
        got = listener.collect(START_TIMEOUT_S, "READY=1")
        got += listener.collect(10.0, "WATCHDOG=1", count=2)
    except TimeoutError as exc:
        raise AssertionError(f"{exc}\n{log.read_text(errors='replace')}") from exc
    assert {pid for pid, _ in got} == {proc.pid}, got
    return next(text for _, text in got if "READY=1" in text)


def aeb(*args: str) -> list[str]:
    return [sys.executable, "-m", "aeb_radar_camera.tools.cli", *args]


def table(folder: Path, port: int, services: str = "") -> Path:
    path = folder / "table.toml"
    path.write_text(f'[router]\nlisten = ["tcp/127.0.0.1:{port}"]\n'
                    f'[zenoh]\nconnect = ["tcp/127.0.0.1:{port}"]\n' + services)
    return path


def test_the_router_unit_notifies_through_up_exec(tmp_path):
    with NotifyListener(tmp_path / "notify") as listener:
        proc = start(aeb("up", "--table", str(table(tmp_path, free_port())), "--exec",
                         "router"), listener, tmp_path / "router.log")
        try:
            said = ready_then_pings(listener, proc, tmp_path / "router.log")
        finally:
            assert stop(proc) == 0
    assert said.startswith("READY=1\nSTATUS=listening on tcp/127.0.0.1:")


def test_the_brake_is_ready_and_watched_without_a_bus(tmp_path):
    # ready once its deadline timer runs: the brake's fail-safe is its service, bus or not
    (tmp_path / "brake.toml").write_text(
        f'[zenoh]\nconnect = ["tcp/127.0.0.1:{free_port()}"]\n'
        f'[brake]\ncommand_keys = ["{EXAMPLE_KEYS / "primary.key"}"]\n'
        f'[brake.serial]\nport = "{tmp_path / "no-actuator"}"\n')
    with NotifyListener(tmp_path / "notify") as listener:
        proc = start(aeb("brake", "--config", str(tmp_path / "brake.toml")), listener,
                     tmp_path / "brake.log")
        try:
            said = ready_then_pings(listener, proc, tmp_path / "brake.log")
        finally:
            assert stop(proc) == 0
    assert said.startswith("READY=1\nSTATUS=deadline timer and actuator link running")


@pytest.mark.parametrize(("service", "config"), [
    ("radar", DEPLOY / "radar-replay.toml"),
    ("camera", DEPLOY / "camera-sim.toml"),
    ("fusion", None),
    ("vehicle", DEPLOY / "vehicle-replay.toml"),
])
def test_radar_camera_fusion_and_the_gateway_are_ready_once_serving_and_watched(tmp_path, router,
                                                                    service, config):
    if config is None:
        config = tmp_path / "fusion.toml"
        config.write_text(f'[fusion]\ncalibration = "{EXAMPLE_CALIBRATION}"\n')
    with NotifyListener(tmp_path / "notify") as listener:
        proc = start(aeb(service, "--config", str(config), "--connect", router), listener,
                     tmp_path / f"{service}.log")
        try:
            said = ready_then_pings(listener, proc, tmp_path / f"{service}.log")
        finally:
            assert stop(proc) == 0
    assert said.startswith(f"READY=1\nSTATUS=serving {service}")


def test_up_notifies_for_itself_and_its_children_do_not(tmp_path):
    (tmp_path / "brake.toml").write_text(
        f'[brake]\ncommand_keys = ["{EXAMPLE_KEYS / "primary.key"}"]\n'
        f'[brake.serial]\nport = "{tmp_path / "none"}"\n')
    path = table(tmp_path, free_port(),
                 '[[service]]\nname = "brake"\naeb = "brake"\nconfig = "brake.toml"\n')
    with NotifyListener(tmp_path / "notify") as listener:
        proc = start(aeb("up", "--colour", "never", "--table", str(path)), listener,
                     tmp_path / "up.log")
        try:
            said = ready_then_pings(listener, proc, tmp_path / "up.log")
        finally:
            assert stop(proc) == 0
    assert said == "READY=1\nSTATUS=supervising router, brake"
    assert "brake: started pid=" in (tmp_path / "up.log").read_text()
