"""docs/deploy.md's "Two boards, step by step", run as written on two boards that are
network namespaces joined by a veth pair with the walk-through's own addresses (ECU A
192.168.10.1, board B 192.168.10.2: both ends inside namespaces this test makes, nothing
leaves them): `aeb init` on each board, the primary's command key carried from B to A,
ECU A's hardware settings pointed at its simulated radar and actuator (ptys; the camera
renders the simulated world), `aeb up --check` on each, `aeb up --table ecu-a.toml` on A
(the brake waits for commands), `aeb up --table ecu-b.toml` on B (the brake arms on fusion's
commands from across the link), `aeb monitor` from B on A's router, and a standing
pedestrian braked for. Needs root (network namespaces); skipped with the reason
otherwise (tests/system/test_multi_board.py has the cut link)."""

import json
import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from tests.support import REPO, START_TIMEOUT_S, ServiceProcess, python_module, wait_for

pytestmark = pytest.mark.slow

A_ADDRESS, B_ADDRESS = "192.168.10.1", "192.168.10.2"    # docs/deploy.md's
ARM_TIMEOUT_S = 240.0       # two stacks starting on a loaded 2-core machine


def ip(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)


@contextmanager
def two_boards() -> Iterator[tuple[str, str]]:
    """Namespaces ECU A and board B, a veth pair between them with the walk-through's
    addresses; yields their names."""
    if os.geteuid() != 0:
        pytest.skip("needs root to create network namespaces (the two-board walk-through)")
    tag = f"{os.getpid() % 100000}"
    ns_a, ns_b, veth_a, veth_b = f"aeb-wa-{tag}", f"aeb-wb-{tag}", f"aw{tag}a", f"aw{tag}b"
    steps = [
        ("netns", "add", ns_a), ("netns", "add", ns_b),
        ("link", "add", veth_a, "netns", ns_a, "type", "veth", "peer", "name", veth_b,
         "netns", ns_b),
        ("-n", ns_a, "addr", "add", f"{A_ADDRESS}/24", "dev", veth_a),
        ("-n", ns_b, "addr", "add", f"{B_ADDRESS}/24", "dev", veth_b),
        ("-n", ns_a, "link", "set", veth_a, "up"), ("-n", ns_b, "link", "set", veth_b, "up"),
        ("-n", ns_a, "link", "set", "lo", "up"), ("-n", ns_b, "link", "set", "lo", "up"),
    ]
    try:
        for step in steps:
            done = ip(*step)
            if done.returncode != 0:
                pytest.skip(f"cannot build the two boards (ip {' '.join(step)}): "
                            f"{done.stderr.strip()}")
        yield ns_a, ns_b
    finally:
        ip("netns", "del", ns_a)          # the veth pair goes with it
        ip("netns", "del", ns_b)


def on(ns: str, *argv: str) -> list[str]:
    return ["ip", "netns", "exec", ns, *argv]


def aeb(*args: str) -> list[str]:
    return python_module("aeb_radar_camera.tools.cli", *args)


def set_table(path: Path, header: str, body: str) -> None:
    """Replace the body of TOML table `header` (up to the next table) by `body`: the
    edits step 4 asks for, as a person makes them in the copy."""
    lines = path.read_text().splitlines()
    start = lines.index(header)
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("[")),
               len(lines))
    path.write_text("\n".join([*lines[:start + 1], body, "", *lines[end:]]) + "\n")


def events(sim: ServiceProcess) -> list[dict[str, object]]:
    out = []
    for line in sim.output().splitlines():
        if line.startswith("{"):
            out.append(json.loads(line))
    return out


def wait_event(sim: ServiceProcess, key: str, timeout_s: float, logs: list[ServiceProcess],
               value: tuple[object, ...] | None = None) -> dict[str, object]:
    """The simulator's first event with `key` (and one of the `value`s, when given)."""
    def match(e: dict[str, object]) -> bool:
        return key in e and (value is None or e[key] in value)

    def found() -> dict[str, object]:
        if not sim.alive() and not any(match(e) for e in events(sim)):
            raise AssertionError(f"the simulator ended:\n{_tails([sim, *logs])}")
        return next((e for e in events(sim) if match(e)), {})
    try:
        return wait_for(found, timeout_s, 0.2, key)
    except TimeoutError:
        raise AssertionError(f"no {key!r} within {timeout_s} s\n{_tails([sim, *logs])}") \
            from None


def _tails(procs: list[ServiceProcess]) -> str:
    return "\n".join(f"--- {p.name} ---\n{p.output()[-4000:]}" for p in procs)


def test_the_two_board_walk_through_as_written_arms_the_brake_and_brakes(tmp_path):
    with two_boards() as (ns_a, ns_b):
        a, b = tmp_path / "ecu-a", tmp_path / "board-b"
        # 1. Install (this installation) and write each board's configs.
        for folder in (a, b):
            done = subprocess.run(aeb("init", str(folder)), capture_output=True, text=True,
                                  timeout=120, cwd=REPO)
            assert done.returncode == 0, done.stderr
        # ... the two copies got their own fresh keys: the primary's key goes from the
        # board that signs (B, fusion) to the board that checks (A, the brake).
        assert (a / "keys" / "primary.key").read_bytes() != \
            (b / "keys" / "primary.key").read_bytes()
        shutil.copy2(b / "keys" / "primary.key", a / "keys" / "primary.key")

        # 4. ECU A's hardware: the simulated ARS408 on an slcan pty, the actuator on a
        # pty, the camera rendering the simulated world.
        sim = ServiceProcess("sim", on(ns_a, *python_module(
            "tests.system.walkthrough_sim", str(tmp_path), "--connect",
            "tcp/127.0.0.1:7447", "--arm-timeout", str(ARM_TIMEOUT_S))), tmp_path)
        procs = [sim]
        try:
            ports_file = tmp_path / "ports.json"
            wait_for(lambda: ports_file.is_file() or not sim.alive(), START_TIMEOUT_S, 0.05,
                     "the simulated hardware")
            assert sim.alive(), sim.output()
            ports = json.loads(ports_file.read_text())
            set_table(a / "radar.toml", "[radar.can]",
                      f'interface = "slcan"\nchannel = "{ports["radar"]}"\n'
                      'options = { sleep_after_open = 0 }')
            set_table(a / "camera.toml", "[camera.source]",
                      'kind = "synthetic"   # SIMULATION: renders the simulated world\n'
                      'factory = "aeb_radar_camera.tools.sim.camera_source:make_source"')
            set_table(a / "ecu-a" / "brake.toml", "[brake.serial]",
                      f'port = "{ports["actuator"]}"')
            checks = {}
            for ns, table in ((ns_a, a / "ecu-a.toml"), (ns_b, b / "ecu-b.toml")):
                check = subprocess.run(on(ns, *aeb("up", "--check", "--table", str(table))),
                                       capture_output=True, text=True, timeout=300,
                                       cwd=REPO)
                assert check.returncode == 0, check.stdout + check.stderr
                checks[ns] = check.stdout
            assert f"tcp/{A_ADDRESS}:7447 free now" in checks[ns_a]

            # 5. Start ECU A: radar, camera and brake up; no commands yet, and the brake
            # says so (an idle brake under `hold` stays idle).
            up_a = ServiceProcess("ecu-a", on(ns_a, *aeb("up", "--table",
                                                         str(a / "ecu-a.toml"))), tmp_path)
            procs.append(up_a)
            waiting = wait_event(sim, "brake_state", ARM_TIMEOUT_S, procs,
                                 ("STANDBY", "FAILSAFE"))
            assert "from primary" in str(waiting["reason"])
            # 2. B reaches A on TCP 7447.
            reach = subprocess.run(on(ns_b, sys.executable, "-c", (
                "import sys, time\nfrom aeb_radar_camera.common.net import wait_listening\n"
                f"wait_listening(7447, {START_TIMEOUT_S}, '{A_ADDRESS}')")),
                capture_output=True, text=True, timeout=120, cwd=REPO)
            assert reach.returncode == 0, reach.stderr

            # 6. Start board B: fusion's commands cross the link, the brake arms.
            up_b = ServiceProcess("board-b", on(ns_b, *aeb("up", "--table",
                                                           str(b / "ecu-b.toml"))), tmp_path)
            procs.append(up_b)
            assert wait_event(sim, "armed", ARM_TIMEOUT_S, procs)["armed"] is True
            seen = [e["brake_state"] for e in events(sim) if "brake_state" in e]
            assert seen[0] != "ARMED" and "ARMED" in seen

            # 7. Check from anywhere on the network: B's side, on A's router.
            monitor = subprocess.run(on(ns_b, *aeb(
                "monitor", "--connect", f"tcp/{A_ADDRESS}:7447", "--once", "--duration",
                "3", "--json")), capture_output=True, text=True, timeout=120, cwd=REPO)
            assert monitor.returncode == 0, monitor.stderr
            snapshot = json.loads(monitor.stdout.splitlines()[-1])
            up = {f"{h['service']}/{h['instance']}" for h in snapshot["health"] if h["alive"]}
            assert {"radar/front", "camera/front", "fusion/primary", "brake/main"} <= up
            assert snapshot["brake"]["state"] in ("ARMED", "BRAKING")   # the scenario runs
            assert snapshot["brake"]["instance"] == "primary"

            # A standing pedestrian: fusion on B decides BRAKE, the brake on A brakes.
            verdict = wait_event(sim, "scenario", ARM_TIMEOUT_S, procs)
            assert verdict["passed"], f"{verdict}\n{_tails(procs)}"
            # the kinematic rule's partial stage at least
            level = verdict["max_level_pct"]
            assert isinstance(level, (int, float)) and level >= 50
            assert sim.proc.wait(120) == 0
            for proc in (up_b, up_a):
                proc.signal(signal.SIGTERM)
                assert proc.proc.wait(60) == 0, proc.output()[-3000:]
        finally:
            for proc in reversed(procs):
                proc.stop()
