"""`aeb router` when an address or port is not available yet: a port still held by a
process going away, or the vehicle network's address not up yet. The router waits it
out, says so, and serves once it can bind; `--check` says what it saw of each address
instead of calling it ok. Only a configuration a restart cannot fix is exit 2."""

import os
import signal
import socket
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from aeb_radar_camera.common.bus import zenoh_message
from aeb_radar_camera.common.net import free_port
from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.common.router import bind_failure, probe
from tests.support import (
    REPO,
    START_TIMEOUT_S,
    ServiceProcess,
    open_bus,
    python_module,
    wait_for,
)

pytestmark = pytest.mark.slow

ZENOH_BIND_ERROR = (
    "cannot open zenoh session: Can not create a new TCP listener bound to "
    "tcp/192.168.10.1:7447: [192.168.10.1:7447: Cannot assign requested address (os error "
    "99) at /root/.cargo/git/checkouts/zenoh-9c599d5ef3e0480e/cc83980/io/zenoh-link-commons"
    "/src/tcp.rs:61.] at /root/.cargo/git/checkouts/zenoh-9c599d5ef3e0480e/cc83980/io/"
    "zenoh-links/zenoh-link-tcp/src/unicast.rs:338.")


@contextmanager
def held_port() -> Iterator[tuple[int, socket.socket]]:
    holder = socket.socket()
    holder.bind(("127.0.0.1", 0))
    holder.listen()
    try:
        yield holder.getsockname()[1], holder
    finally:
        holder.close()


def test_zenohs_build_paths_are_left_out_and_a_bind_failure_is_recognised():
    text = zenoh_message(ValueError(ZENOH_BIND_ERROR))
    assert ".cargo" not in text and ".rs:" not in text
    assert text.endswith("Cannot assign requested address (os error 99)]")
    assert bind_failure(text) == bind_failure(ZENOH_BIND_ERROR) == (
        "tcp/192.168.10.1:7447", 99)
    assert bind_failure("invalid zenoh configuration: listen/endpoints") is None


def waiting_router(tmp_path, argv: list[str]) -> ServiceProcess:
    """A router started with `argv`, once it said it waits for an address."""
    router = ServiceProcess("router", argv, tmp_path)
    try:
        wait_for(lambda: "listen_address_unavailable" in router.output()
                 or not router.alive(), START_TIMEOUT_S, 0.05, "the router to say it waits")
        assert router.alive(), router.output()
    except BaseException:
        router.stop()
        raise
    return router


def test_a_port_still_held_is_waited_for_then_served(tmp_path):
    with held_port() as (port, holder):
        router = waiting_router(tmp_path, python_module(
            "aeb_radar_camera.tools.cli", "router", "--listen", f"tcp/127.0.0.1:{port}"))
        try:
            log = router.output()
            assert f"endpoint=tcp/127.0.0.1:{port}" in log and "already in use" in log
            assert ".cargo" not in log
            holder.close()                     # the old process is gone
            wait_for(lambda: "router_ready" in router.output() or not router.alive(),
                     START_TIMEOUT_S, 0.05, "the router to serve")
            assert router.alive(), router.output()
            with open_bus(f"tcp/127.0.0.1:{port}") as bus:
                assert bus.session.info.routers_zid()
            router.signal(signal.SIGTERM)
            assert router.proc.wait(30) == 0
        finally:
            router.stop()


def test_a_router_stopped_while_it_waits_exits_cleanly(tmp_path):
    with held_port() as (port, _):
        router = waiting_router(tmp_path, python_module(
            "aeb_radar_camera.tools.cli", "router", "--listen", f"tcp/127.0.0.1:{port}"))
        try:
            router.signal(signal.SIGINT)
            assert router.proc.wait(30) == 0, router.output()
        finally:
            router.stop()


def test_check_says_what_it_saw_of_each_address_not_just_ok():
    with held_port() as (port, _):
        free = free_port()
        done = subprocess.run(python_module(
            "aeb_radar_camera.tools.cli", "router", "--listen", f"tcp/127.0.0.1:{port}", "--listen",
            f"tcp/127.0.0.1:{free}", "--check"), capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert f"tcp/127.0.0.1:{port} not available now: Address already in use" in done.stdout
    assert f"tcp/127.0.0.1:{free} free now" in done.stdout
    assert probe("ws/127.0.0.1:0") == "free now" and probe("unixsock-stream//tmp/x") == \
        "not probed"


def ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, timeout=30)


@contextmanager
def namespace() -> Iterator[str]:
    if os.geteuid() != 0:
        pytest.skip("needs root for a network namespace (the held-port tests run "
                    "without it)")
    ns = f"aeb-rt-{os.getpid()}"
    try:
        ip("netns", "add", ns)
        ip("netns", "exec", ns, "ip", "link", "set", "lo", "up")
    except subprocess.CalledProcessError as exc:
        pytest.skip(f"cannot make a network namespace: {exc.stderr}")
    try:
        yield ns
    finally:
        subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=30)


def test_ecu_as_router_waits_for_its_vehicle_network_address(tmp_path):
    # ECU A's shipped router config listens on 192.168.10.1, here on a board (a network
    # namespace of its own) whose address comes up after the router started
    with namespace() as ns:
        router = waiting_router(tmp_path, ["ip", "netns", "exec", ns, *python_module(
            "aeb_radar_camera.tools.cli", "router", "--config-file",
            str(DEPLOY / "zenoh" / "ecu-a-router.json5"))])
        try:
            assert "endpoint=tcp/192.168.10.1:7447" in router.output()
            ip("netns", "exec", ns, "ip", "addr", "add", "192.168.10.1/24", "dev", "lo")
            wait_for(lambda: "router_ready" in router.output() or not router.alive(),
                     START_TIMEOUT_S, 0.05, "the router to serve")
            assert router.alive(), router.output()
            reached = subprocess.run(["ip", "netns", "exec", ns, sys.executable, "-c",
                                      "import sys; "
                                      "from aeb_radar_camera.common.net import port_open; "
                                      "sys.exit(not port_open(7447, '192.168.10.1'))"],
                                     capture_output=True, text=True, timeout=60, cwd=REPO)
            assert reached.returncode == 0, reached.stderr
            router.signal(signal.SIGTERM)
            assert router.proc.wait(30) == 0
        finally:
            router.stop()
