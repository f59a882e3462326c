"""The whole stack under simulation for system tests: every service as its own process
(tests.support.ServiceProcess) behind a router, the simulated radar on a CAN link that
crosses processes, the simulated actuator on a pty, and the closed-loop simulator in
the test process."""

import os
import subprocess
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

import can
import pytest

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.tools.sim.actuator import SimActuator
from aeb_radar_camera.tools.sim.can_links import SlcanPtyLink
from aeb_radar_camera.tools.sim.radar_feed import FrameSink, PythonCanSink, RadarFeed
from aeb_radar_camera.tools.sim.runner import SimActuatorView, Simulator
from aeb_radar_camera.tools.sim.scenario import RadarLook
from aeb_radar_camera.tools.sim.stack import SERVICES, TOKENS, StackConfigs, write_configs
from tests.support import START_TIMEOUT_S, HealthWatch, ServiceProcess, open_bus, python_module

# The brake's heartbeat above one radar cycle: while commands flow, every actuator line
# is a command line, so cycles and lines pair exactly (tools/sim/latency.py).
HEARTBEAT_MS = 120.0


@dataclass
class SimStack:
    endpoint: str
    bus: Bus
    health: HealthWatch
    procs: dict[str, ServiceProcess]
    actuator: SimActuator
    feed: RadarFeed
    sim: Simulator
    configs: StackConfigs

    def logs(self) -> str:
        return "\n".join(f"--- {n} ---\n{p.output()[-3000:]}" for n, p in self.procs.items())


def create_vcan() -> str:
    """A new vcan interface (removed by `remove_vcan`); skips the test with the reason
    when the kernel or the permissions do not allow it."""
    name = f"vcan{os.getpid() % 100000}"
    for cmd in (["ip", "link", "add", "dev", name, "type", "vcan"],
                ["ip", "link", "set", "up", name]):
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
        except FileNotFoundError:
            pytest.skip("no `ip` command: cannot create a vcan interface")
        if proc.returncode != 0:
            remove_vcan(name)
            pytest.skip(f"cannot create a vcan interface ({' '.join(cmd)}): "
                        f"{proc.stderr.strip() or proc.returncode} (the kernel has no vcan "
                        "module, or no permission); the slcan variant covers the same path")
    return name


def remove_vcan(name: str) -> None:
    subprocess.run(["ip", "link", "del", name], capture_output=True, timeout=30, check=False)


@contextmanager
def sim_stack(tmp_path: Path, endpoint: str, can_variant: str = "slcan",
              wrap: Callable[[str, list[str]], list[str]] | None = None,
              connect: dict[str, str] | None = None) -> Iterator[SimStack]:
    """Start everything; yield once every liveliness token is up and the brake is armed.

    `wrap(service, argv)` may change a service's command line (e.g. run it in another
    network namespace); `connect[service]` overrides the endpoint a service connects to.
    """
    with ExitStack() as stack:
        sink: FrameSink
        if can_variant == "slcan":
            link = stack.enter_context(SlcanPtyLink())
            channel, interface = link.path, "slcan"
            sink = link
        else:
            channel, interface = create_vcan(), "socketcan"
            stack.callback(remove_vcan, channel)
            can_bus = can.Bus(interface="socketcan", channel=channel)
            stack.callback(can_bus.shutdown)
            sink = PythonCanSink(can_bus)
        actuator, _pair = SimActuator.on_pty(tmp_path / "actuator")
        actuator.start()
        stack.callback(actuator.stop)
        configs = write_configs(tmp_path / "configs", endpoint, str(tmp_path / "actuator"),
                                channel, interface, heartbeat_ms=HEARTBEAT_MS)
        procs: dict[str, ServiceProcess] = {}
        for name in SERVICES:
            ep = (connect or {}).get(name, endpoint)
            argv = python_module(f"aeb_radar_camera.services.{name}", "--config",
                                 str(configs.of(name)),
                                 "--connect", ep)
            procs[name] = ServiceProcess(name, wrap(name, argv) if wrap else argv, tmp_path)
            stack.callback(procs[name].stop)
        bus = stack.enter_context(open_bus(endpoint, source="sim"))
        health = HealthWatch(bus)
        for name in SERVICES:
            try:
                health.wait_alive(*TOKENS[name], START_TIMEOUT_S)
            except TimeoutError:
                logs = "\n".join(f"--- {n} ---\n{p.output()[-2000:]}" for n, p in procs.items())
                raise AssertionError(f"{name} never declared its token\n{logs}") from None
        feed = RadarFeed(sink, RadarLook())
        sim = Simulator(bus, feed, SimActuatorView(actuator)).start()
        stack.callback(sim.stop)
        result = SimStack(endpoint, bus, health, procs, actuator, feed, sim, configs)
        assert sim.wait_settled(START_TIMEOUT_S), \
            f"never armed: fusion {sim.decision!r}, brake {sim.brake_state!r}\n{result.logs()}"
        yield result


def brake_lines(actuator: SimActuator, start_ns: int, end_ns: int) -> list[tuple[int, int]]:
    """(time, level) of every command line the actuator received in [start, end]."""
    return [(r.t_ns, r.cmd.level_pct) for r in actuator.commands_since(start_ns)
            if r.t_ns <= end_ns]
