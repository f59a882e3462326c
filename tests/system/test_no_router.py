"""Radar, camera, fusion and the vehicle gateway, and the bus tools, started with no
router reachable: each says which endpoint it waits for, keeps waiting, and stops
cleanly (exit 0) on SIGTERM or SIGINT."""

import signal
import subprocess

import pytest

from aeb_radar_camera.common.net import free_port
from tests.support import REPO, START_TIMEOUT_S, ServiceProcess, python_module, wait_for

SERVICES = {
    "radar": ("aeb_radar_camera.services.radar", "deploy/radar-replay.toml"),
    "camera": ("aeb_radar_camera.services.camera", "deploy/camera-sim.toml"),
    "fusion": ("aeb_radar_camera.services.fusion", "deploy/fusion.toml"),
    "vehicle": ("aeb_radar_camera.services.vehicle", "deploy/vehicle-replay.toml"),
}


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
@pytest.mark.parametrize("service", sorted(SERVICES))
def test_waits_for_the_router_visibly_and_stops_on_a_signal(tmp_path, service, sig):
    module, config = SERVICES[service]
    # nothing listens on a free port
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    proc = ServiceProcess(service, python_module(module, "--config", str(REPO / config),
                                                 "--connect", endpoint), tmp_path)
    waits_then_stops_on(proc, endpoint, sig, service)


def waits_then_stops_on(proc: ServiceProcess, endpoint: str, sig: signal.Signals,
                        what: str) -> None:
    """`proc` says it waits for the router at `endpoint`, and exits 0 on `sig`."""
    try:
        wait_for(lambda: "waiting_for_router" in proc.output() or not proc.alive(),
                 START_TIMEOUT_S, 0.05, f"{what} to say it waits for the router")
        assert proc.alive(), proc.output()
        assert endpoint in proc.output()
        proc.signal(sig)
        try:
            code = proc.proc.wait(START_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            pytest.fail(f"{what} still running {START_TIMEOUT_S} s after {sig.name}:\n"
                        f"{proc.output()}")
        assert code == 0, proc.output()
        assert "Traceback" not in proc.output()
    finally:
        proc.stop()


BUS_TOOLS = {
    "monitor": ("monitor", "--once"),
    "echo": ("echo", "radar_tracks"),
    "hz": ("hz", "radar_tracks"),
    "ab-report": ("ab-report",),
    "calib-capture": ("calib-capture", "--out", "{tmp}/capture"),
}


@pytest.mark.parametrize("tool", sorted(BUS_TOOLS))
def test_a_bus_tool_waiting_for_the_router_stops_on_a_signal(tmp_path, tool):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    # No give-up time: only the signal can end the wait.
    args = [a.format(tmp=tmp_path) for a in BUS_TOOLS[tool]]
    proc = ServiceProcess(tool, python_module("aeb_radar_camera.tools.cli", *args, "--connect",
                                              endpoint,
                                              "--connect-timeout", "0"), tmp_path)
    waits_then_stops_on(proc, endpoint, signal.SIGTERM, f"aeb {tool}")
