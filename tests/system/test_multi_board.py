"""Two boards on one machine: fusion alone in its own network namespace ("board B"),
connected over a veth pair to the router in the root namespace ("ECU A", with radar,
camera and brake). Brake commands flow across the link and brake for a threat; the link
taken down leads to FAILSAFE within the brake's deadline. Needs root (network
namespaces); skipped with the reason otherwise."""

import os
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from aeb_radar_camera.common.config.brake import BrakeConfig
from aeb_radar_camera.common.config.loader import load_config
from aeb_radar_camera.common.keys import BRAKE_STATUS
from aeb_radar_camera.common.messages import BrakeState
from aeb_radar_camera.services.brake.shell import TIMER_PERIOD_S
from aeb_radar_camera.tools.sim.scenario import find_scenario, load_scenario
from tests.support import (
    START_TIMEOUT_S,
    Collector,
    ServiceProcess,
    free_port,
    port_open,
    python_module,
    wait_for,
)
from tests.system.stack_support import brake_lines, sim_stack

pytestmark = pytest.mark.slow

SCHEDULING_SLACK_MS = 50.0


def ip(*args: str, netns: str = "") -> subprocess.CompletedProcess[str]:
    cmd = ["ip", *(["netns", "exec", netns, "ip"] if netns else []), *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=30, check=False)


@contextmanager
def board_b() -> Iterator[tuple[str, str, str]]:
    """A network namespace joined to the root namespace by a veth pair; yields
    (namespace, root-side interface, root-side address)."""
    if os.geteuid() != 0:
        pytest.skip("needs root to create network namespaces (multi-board test)")
    tag = f"{os.getpid() % 100000}"
    ns, side_a, side_b = f"aeb-b-{tag}", f"aeb{tag}a", f"aeb{tag}b"
    net = f"10.77.{os.getpid() % 250}"
    steps = [
        (["netns", "add", ns], ""),
        (["link", "add", side_a, "type", "veth", "peer", "name", side_b], ""),
        (["link", "set", side_b, "netns", ns], ""),
        (["addr", "add", f"{net}.1/30", "dev", side_a], ""),
        (["link", "set", side_a, "up"], ""),
        (["addr", "add", f"{net}.2/30", "dev", side_b], ns),
        (["link", "set", side_b, "up"], ns),
        (["link", "set", "lo", "up"], ns),
    ]
    try:
        for args, where in steps:
            proc = ip(*args, netns=where)
            if proc.returncode != 0:
                pytest.skip(f"cannot build the two-board network (ip {' '.join(args)}): "
                            f"{proc.stderr.strip()}")
        yield ns, side_a, f"{net}.1"
    finally:
        ip("link", "del", side_a)
        ip("netns", "del", ns)


def test_fusion_on_board_b_brakes_and_a_cut_link_fails_safe(tmp_path):
    with board_b() as (ns, side_a, address):
        port = free_port()
        local, remote = f"tcp/127.0.0.1:{port}", f"tcp/{address}:{port}"
        router = ServiceProcess("router", python_module("aeb_radar_camera.common.router",
                                                        "--listen", local,
                                                        "--listen", remote), tmp_path)
        try:
            wait_for(lambda: port_open(port) or not router.alive(), START_TIMEOUT_S, 0.05,
                     "router port")
            assert router.alive(), router.output()

            def on_board_b(service: str, argv: list[str]) -> list[str]:
                return ["ip", "netns", "exec", ns, *argv] if service == "fusion" else argv

            with sim_stack(tmp_path, local, wrap=on_board_b,
                           connect={"fusion": remote}) as st:
                # Brake commands flow from board B: the brake is armed on them and the
                # actuator gets a line per command.
                statuses = Collector()
                st.bus.subscribe(BRAKE_STATUS, statuses)
                first = statuses.wait_until(lambda m: m.last_cmd_seq >= 0, 30)
                later = statuses.wait_until(lambda m: m.last_cmd_seq >= first.last_cmd_seq + 10,
                                            30)
                assert later.state is BrakeState.ARMED and later.instance == "primary"

                run = st.sim.run(load_scenario(find_scenario("pedestrian_standing_20kph")))
                assert run.verdict.passed, f"{run.verdict}\n{st.logs()}"
                assert any(level > 0 for _, level in
                           brake_lines(st.actuator, run.start_mono_ns, run.end_mono_ns))
                assert st.sim.wait_settled(60), st.logs()

                # The cable is pulled: fusion is still running, its commands stop arriving.
                cfg = load_config(st.configs.brake, BrakeConfig)
                after = Collector()
                st.bus.subscribe(BRAKE_STATUS, after)
                after.wait_until(lambda m: m.state is BrakeState.ARMED, 30)
                assert ip("link", "set", side_a, "down").returncode == 0
                failsafe = after.wait_until(lambda m: m.state is BrakeState.FAILSAFE, 30)
                silent_ms = (failsafe.state_since_mono_ns - failsafe.last_cmd_rx_mono_ns) / 1e6
                bound_ms = cfg.brake.deadline_ms + TIMER_PERIOD_S * 1000
                print(f"\nlink down: FAILSAFE {silent_ms:.1f} ms after the last command "
                      f"(bound {bound_ms:.0f} ms)")
                assert cfg.brake.deadline_ms <= silent_ms <= bound_ms + SCHEDULING_SLACK_MS
                assert st.procs["fusion"].alive()
        finally:
            router.stop()
