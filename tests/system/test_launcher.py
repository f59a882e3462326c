"""`aeb up` as a process: table validation, log prefixes, restarts with backoff, a clean
stop with no orphans (also when the launcher itself is killed), and the router it starts."""

import functools
import os
import signal
import sys
import textwrap
from pathlib import Path

import pytest

from aeb_radar_camera.common.service import STOP_GRACE_S
from tests.support import (
    START_TIMEOUT_S,
    HealthWatch,
    ServiceProcess,
    free_port,
    open_bus,
    port_open,
    python_module,
    wait_for,
)

pytestmark = pytest.mark.slow


def up(*args: str) -> list[str]:
    return python_module("aeb_radar_camera.tools.cli", "up", "--colour", "never", *args)


def run_check(tmp_path: Path, table: str, *extra: str):
    import subprocess

    path = tmp_path / "table.toml"
    path.write_text(textwrap.dedent(table))
    return subprocess.run(up("--table", str(path), "--check", *extra), capture_output=True,
                          text=True, timeout=120)


def pid_gone(pid: int) -> bool:
    """True once the process no longer exists or is a zombie awaiting its reaper."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] == "Z"
    except FileNotFoundError:
        return True


def process_state(pid: int) -> str:
    """State, wait channel and threads of a process, for a failure message."""
    try:
        status = Path(f"/proc/{pid}/status").read_text().splitlines()
        wchan = Path(f"/proc/{pid}/wchan").read_text()
    except OSError as exc:
        return f"unreadable ({exc})"
    keep = [ln for ln in status if ln.split(":")[0] in ("State", "PPid", "Threads", "SigPnd",
                                                           "ShdPnd", "SigBlk", "SigCgt")]
    return "; ".join(keep) + f"; wchan {wchan}"


def lines_of(proc: ServiceProcess, prefix: str) -> list[str]:
    return [ln for ln in proc.output().splitlines() if ln.startswith(prefix)]


@pytest.mark.parametrize(
    ("table", "named"),
    [
        ('[[service]]\nname = "radar"\naeb = "radar"\ncolour = "red"\n', "colour"),
        ('[[service]]\nname = "radar"\naeb = "radar"\nconfig = "missing/radar.toml"\n',
         "missing/radar.toml"),
        ('[[service]]\nname = "radar"\naeb = "rader"\n', "unknown aeb command 'rader'"),
        ('[[service]]\nname = "radar"\naeb = "radar"\nexec = ["x"]\n', "exactly one"),
        ('[[service]]\nname = "a"\naeb = "radar"\n[[service]]\nname = "a"\naeb = "brake"\n',
         "appears twice"),
        ('[router]\nconfig = "nope.json5"\n[[service]]\nname = "a"\naeb = "radar"\n',
         "nope.json5"),
        ('[restart]\nmode = "sometimes"\n', "$.restart.mode"),
        ('[[service]]\nname = "x"\nexec = ["no-such-program-anywhere"]\n', "not found"),
        ('cpu_latency_us = -1\n[[service]]\nname = "a"\naeb = "radar"\n',
         "$.cpu_latency_us"),
    ],
)
def test_invalid_tables_exit_2_naming_the_problem(tmp_path, table, named):
    proc = run_check(tmp_path, table)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert named in proc.stderr
    assert "table.toml" in proc.stderr


def test_the_tables_cpu_latency_request_is_held_for_the_run_and_a_refusal_is_said(tmp_path):
    import struct

    from aeb_radar_camera.tools.launch.main import held_cpu_latency

    said: list[str] = []
    stand_in = tmp_path / "cpu_dma_latency"
    stand_in.write_bytes(b"")
    with held_cpu_latency(0, said.append, device=str(stand_in)):
        assert struct.unpack("i", stand_in.read_bytes()) == (0,)
    with held_cpu_latency(5, said.append, device=str(tmp_path / "missing")):
        pass                                  # the stack runs all the same
    with held_cpu_latency(None, said.append, device=str(tmp_path / "missing")):
        pass                                  # nothing asked, nothing said
    assert len(said) == 2
    assert said[0].startswith("cpu_latency_us=0: ") and "refused" in said[1]


def test_check_prints_resolved_commands_and_only_filters(tmp_path):
    (tmp_path / "fusion.toml").write_text("")
    table = """
        workdir = "."
        [router]
        listen = ["tcp/127.0.0.1:7999"]
        [zenoh]
        connect = ["tcp/127.0.0.1:7999"]
        [[service]]
        name = "fusion"
        aeb = "fusion"
        config = "fusion.toml"
        env = { OMP_NUM_THREADS = "1" }
        [[service]]
        name = "brake"
        aeb = "brake"
        restart = "always"
    """
    proc = run_check(tmp_path, table, "--only", "fusion")
    assert proc.returncode == 0, proc.stderr
    lines = [ln for ln in proc.stdout.splitlines() if not ln.startswith(" ")]
    assert [ln.split(":")[0] for ln in lines] == ["router", "fusion"]
    assert "--listen tcp/127.0.0.1:7999" in lines[0]
    assert f"--config {tmp_path / 'fusion.toml'}" in lines[1]
    assert "--connect tcp/127.0.0.1:7999" in lines[1]
    assert "OMP_NUM_THREADS=1" in lines[1]
    assert "[restart=on-failure]" in lines[1]
    bad = run_check(tmp_path, table, "--only", "fusion,radar")
    assert bad.returncode == 2 and "['radar']" in bad.stderr


CRASHER = """
import sys
print("hello from crasher", flush=True)
sys.exit(3)
"""

STUBBORN = """
import os, signal, time
signal.signal(signal.SIGTERM, signal.SIG_IGN)
print(f"stubborn pid={os.getpid()}", flush=True)
while True:
    time.sleep(1)
"""

PARENT = """
import subprocess, sys, time
child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
print(f"grandchild pid={child.pid}", flush=True)
while True:
    time.sleep(1)
"""

ALIVE = """
import os, sys, threading
from aeb_radar_camera.common.service import stop_event_on_signals
from tests.support import open_bus
stop = stop_event_on_signals()
with open_bus(sys.argv[1]) as bus:
    token = bus.declare_health("alive", "test")
    print(f"alive pid={os.getpid()}", flush=True)
    stop.wait()
print("alive stopping cleanly", flush=True)
"""


def supervised_table(tmp_path: Path, port: int) -> Path:
    scripts = {"crasher": CRASHER, "stubborn": STUBBORN, "parent": PARENT, "alive": ALIVE}
    for name, code in scripts.items():
        (tmp_path / f"{name}.py").write_text(code)
    repo = Path(__file__).resolve().parents[2]
    endpoint = f"tcp/127.0.0.1:{port}"
    table = tmp_path / "table.toml"
    table.write_text(textwrap.dedent(f"""
        workdir = "{repo}"
        stop_grace_s = 20.0
        [router]
        listen = ["{endpoint}"]
        [restart]
        mode = "on-failure"
        backoff = {{ initial_s = 0.2, max_s = 0.4, stable_after_s = 30.0 }}
        [[service]]
        name = "crasher"
        exec = ["{sys.executable}", "{tmp_path / 'crasher.py'}"]
        [[service]]
        name = "stubborn"
        exec = ["{sys.executable}", "{tmp_path / 'stubborn.py'}"]
        stop_grace_s = 1.0
        [[service]]
        name = "parent"
        exec = ["{sys.executable}", "{tmp_path / 'parent.py'}"]
        [[service]]
        name = "alive"
        exec = ["{sys.executable}", "{tmp_path / 'alive.py'}", "{endpoint}"]
        env = {{ PYTHONPATH = "{repo}" }}
    """))
    return table


def pid_from(proc: ServiceProcess, marker: str) -> int:
    def find() -> int:
        for line in proc.output().splitlines():
            if marker in line:
                return int(line.rsplit("=", 1)[1])
        return 0

    return wait_for(find, START_TIMEOUT_S, 0.05, marker)


def test_up_runs_router_and_services_restarts_and_stops_cleanly(tmp_path):
    port = free_port()
    table = supervised_table(tmp_path, port)
    launcher = ServiceProcess("up", up("--table", str(table)), tmp_path)
    try:
        # The router the launcher started carries the service's liveliness token.
        wait_for(lambda: port_open(port), START_TIMEOUT_S, 0.05, "router port")
        with open_bus(f"tcp/127.0.0.1:{port}") as bus:
            HealthWatch(bus).wait_alive("alive", "test")
        # A crashing service is restarted with backoff; its lines carry its name.
        wait_for(lambda: len(lines_of(launcher, "crasher  | hello from crasher")) >= 3,
                 START_TIMEOUT_S, 0.05, "three runs of crasher")
        out = launcher.output()
        assert "crasher: exit 3: restarting in 0.2 s" in out
        assert "crasher: exit 3: restarting in 0.4 s" in out
        stubborn = pid_from(launcher, "stubborn pid=")
        grandchild = pid_from(launcher, "grandchild pid=")
        alive = pid_from(launcher, "alive pid=")

        launcher.signal(signal.SIGTERM)
        wait_for(lambda: not launcher.alive(), 60, 0.05, "launcher exit")
        out = launcher.output()
        assert launcher.proc.returncode == 0, out
        assert "stubborn: still running after 1.0 s, SIGKILL" in out
        assert "alive    | alive stopping cleanly" in out
        assert "alive: stopped (exit 0)" in out
        for pid in (stubborn, grandchild, alive):
            wait_for(functools.partial(pid_gone, pid), 10, 0.05, f"pid {pid} gone")
        assert not port_open(port)
    finally:
        launcher.stop()


def test_children_die_with_a_killed_launcher(tmp_path):
    port = free_port()
    table = supervised_table(tmp_path, port)
    launcher = ServiceProcess("up", up("--table", str(table), "--only", "parent,alive"),
                              tmp_path)
    try:
        grandchild = pid_from(launcher, "grandchild pid=")
        alive = pid_from(launcher, "alive pid=")
        wait_for(lambda: port_open(port), START_TIMEOUT_S, 0.05, "router port")
        os.kill(launcher.pid, signal.SIGKILL)
        # Each direct child got SIGTERM from the kernel (PR_SET_PDEATHSIG); a stop path
        # that hangs is cut off by the service's own watchdog (common/service.py).
        try:
            wait_for(lambda: pid_gone(alive), STOP_GRACE_S + 15, 0.05, "alive gone")
        except TimeoutError:
            raise AssertionError(f"alive (pid {alive}) still there: {process_state(alive)}\n"
                                 f"launcher output:\n{launcher.output()}") from None
        wait_for(lambda: not port_open(port), 30, 0.05, "router gone")
    finally:
        launcher.stop()
        # The grandchild is not covered by the parent-death signal (its parent, the
        # service, was the one that died quietly): say so rather than leak it.
        if not pid_gone(grandchild):
            os.kill(grandchild, signal.SIGKILL)
