"""The simulated actuator, driven by this test as the host over a real pty."""

import json
import math
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import serial

from aeb_radar_camera.common.clock import mono_ns
from aeb_radar_camera.services.brake.protocol import (
    FAULT_WATCHDOG,
    Ack,
    ActuatorState,
    BadLine,
    Command,
    Fault,
    HostMode,
    LineReader,
    Nak,
    ProtocolError,
    crc16,
    decode,
    encode,
)
from aeb_radar_camera.tools.sim.actuator import SimActuator, SimEvent, WatchdogPolicy, control
from tests.support import REPO, wait_for


class Host:
    """The host side of the line, as the brake service would open it."""

    def __init__(self, path: Path) -> None:
        self.port = serial.Serial(str(path), 115200, timeout=0.05)
        self.reader = LineReader()
        self.frames: list[object] = []
        self.seq = 0

    def send(self, level: int, ttl_ms: int = 250, mode: HostMode = HostMode.ARMED) -> int:
        seq, self.seq = self.seq, self.seq + 1
        self.port.write(encode(Command(seq, level, ttl_ms, mode)))
        return seq

    def poll(self) -> list[object]:
        data = self.port.read(self.port.in_waiting or 1)
        for item in self.reader.feed(data):
            if isinstance(item, BadLine):
                self.frames.append(item)
                continue
            try:
                self.frames.append(decode(item))
            except ProtocolError as exc:
                self.frames.append(exc.reason)
        return self.frames

    def wait(self, pred, timeout_s: float = 10.0):
        return wait_for(lambda: [f for f in self.poll() if pred(f)], timeout_s)[0]


@pytest.fixture
def sim_host(tmp_path) -> Iterator[tuple[SimActuator, Host]]:
    sim, pair = SimActuator.on_pty(tmp_path / "act", tau_s=0.2)
    with sim:
        host = Host(tmp_path / "act")
        try:
            yield sim, host
        finally:
            host.port.close()
            pair.remove()


def test_acknowledges_with_a_first_order_position(sim_host):
    sim, host = sim_host
    events: list[SimEvent] = []
    sim.add_listener(events.append)
    seq = host.send(100)
    ack = host.wait(lambda f: isinstance(f, Ack) and f.seq == seq)
    assert ack.state is ActuatorState.OK and ack.position_pct < 5.0
    applied = sim.history[-1].t_ns
    assert sim.position_pct(applied + 200_000_000) == pytest.approx(100 * (1 - math.exp(-1)))
    assert sim.position_pct(applied + 2_000_000_000) == pytest.approx(100.0, abs=0.01)
    wait_for(lambda: events, 5)
    assert events[0].kind == "command" and events[0].cmd is not None
    assert events[0].cmd.level_pct == 100 and events[0].target_pct == 100.0


def test_a_line_is_stamped_when_read_even_while_the_simulator_holds_its_lock(sim_host):
    # The latency benchmark times commands by this stamp: another thread of the simulator
    # holding the lock (the physics, a snapshot) must not make the line look late.
    sim, host = sim_host
    ep = sim._endpoint
    assert ep is not None
    read = threading.Event()
    plain_read = ep.read_available

    def read_and_tell() -> bytes:
        data = plain_read()
        if data:
            read.set()
        return data

    ep.read_available = read_and_tell
    with sim._lock:
        seq = host.send(40)
        assert read.wait(10), "the actuator never read the line"
        read_seen = mono_ns()
        time.sleep(0.05)        # the stimulus: the lock held 50 ms after the read
    host.wait(lambda f: isinstance(f, Ack) and f.seq == seq)
    received = sim.commands_since(0)[-1]
    assert received.cmd.seq == seq
    assert received.t_ns < read_seen + 40_000_000


@pytest.mark.parametrize("policy", [WatchdogPolicy.HOLD, WatchdogPolicy.RELEASE])
def test_own_watchdog_applies_its_failsafe_and_says_so(tmp_path, policy):
    sim, pair = SimActuator.on_pty(tmp_path / "act", watchdog_policy=policy,
                                   fault_repeat_s=0.1)
    with sim:
        host = Host(tmp_path / "act")
        host.send(40, ttl_ms=50)
        fault = host.wait(lambda f: isinstance(f, Fault))
        assert fault == Fault(FAULT_WATCHDOG, "watchdog ttl expired")
        snap = sim.snapshot()
        assert snap.watchdog_tripped and snap.warning and snap.watchdog_trips == 1
        assert snap.target_pct == (40.0 if policy is WatchdogPolicy.HOLD else 0.0)
        wait_for(lambda: sum(isinstance(f, Fault) for f in host.poll()) >= 2, 10,
                 what="the fault line repeated")
        seq = host.send(10)
        host.wait(lambda f: isinstance(f, Ack) and f.seq == seq)
        assert not sim.snapshot().watchdog_tripped and sim.snapshot().target_pct == 10.0
        host.port.close()
    pair.remove()


def test_unusable_lines_get_a_nak_and_change_nothing(sim_host):
    sim, host = sim_host
    seq = host.send(30)
    host.wait(lambda f: isinstance(f, Ack) and f.seq == seq)
    host.port.write(b"$C,1,99,80,250,A*0000\n")                      # bad CRC
    host.port.write(b"$C,1,99,101,250,A*%04X\n" % crc16(b"C,1,99,101,250,A"))
    host.port.write(encode(Ack(1, 0.0, ActuatorState.OK)))            # not for the actuator

    def naks() -> list[Nak]:
        return [f for f in host.poll() if isinstance(f, Nak)]

    wait_for(lambda: len(naks()) >= 3, 10, what="three NAKs")
    assert [n.reason for n in naks()] == [BadLine.CRC, BadLine.RANGE, BadLine.TYPE]
    assert sim.snapshot().target_pct == 30.0 and sim.snapshot().last_seq == seq


def test_injected_faults(sim_host):
    sim, host = sim_host
    sim.set_no_ack(True)
    seq = host.send(20)
    wait_for(lambda: sim.snapshot().last_seq == seq, 5)
    sim.set_no_ack(False)
    seq2 = host.send(20)
    host.wait(lambda f: isinstance(f, Ack) and f.seq == seq2)
    assert not [f for f in host.frames if isinstance(f, Ack) and f.seq == seq]
    sim.raise_fault(3, "motor overcurrent")
    assert host.wait(lambda f: isinstance(f, Fault)) == Fault(3, "motor overcurrent")
    frozen = sim.snapshot().target_pct
    seq3 = host.send(90)
    ack = host.wait(lambda f: isinstance(f, Ack) and f.seq == seq3)
    assert ack.state is ActuatorState.FAULT and sim.snapshot().target_pct == frozen
    sim.clear_fault()
    assert sim.snapshot().target_pct == 90.0
    sent = sim.inject_garbage(200)
    assert len(sent) >= 200
    host.wait(lambda f: isinstance(f, BadLine))


def test_disconnect_frees_the_pty_and_reconnect_comes_back_behind_the_path(sim_host, tmp_path):
    sim, host = sim_host
    sim.disconnect()
    with pytest.raises(serial.SerialException):
        for _ in range(100):
            host.port.read(1)
            host.port.write(b"x")
    host.port.close()
    sim.reconnect()
    host2 = Host(tmp_path / "act")
    seq = host2.send(5)
    host2.wait(lambda f: isinstance(f, Ack) and f.seq == seq)
    host2.port.close()
    assert sim.connects == 2


def test_control_lines(sim_host):
    sim, _ = sim_host
    assert control(sim, "noack on") == "ok" and sim._no_ack
    assert control(sim, "fault 4 supply low") == "ok"
    assert json.loads(control(sim, "status"))["state"] == "FAULT"
    assert control(sim, "clear") == "ok"
    with pytest.raises(ValueError, match="unknown control line"):
        control(sim, "explode")


def test_runs_as_its_own_process_with_a_status_file(tmp_path):
    link, status = tmp_path / "act", tmp_path / "status.json"
    proc = subprocess.Popen(
        [sys.executable, "-m", "aeb_radar_camera.tools.sim.actuator", "--pty-link", str(link),
         "--status-file", str(status), "--status-hz", "50"],
        cwd=REPO, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None and proc.stdin is not None
        assert proc.stdout.readline().strip() == f"ready {link}"
        host = Host(link)
        seq = host.send(80)
        host.wait(lambda f: isinstance(f, Ack) and f.seq == seq)

        def position() -> float:
            try:
                return float(json.loads(status.read_text())["position_pct"])
            except (FileNotFoundError, json.JSONDecodeError):
                return 0.0

        wait_for(lambda: position() > 40.0, 10, what="position in the status file")
        proc.stdin.write("fault 3 motor overcurrent\n")
        proc.stdin.flush()
        assert proc.stdout.readline().strip() == "ok"
        assert host.wait(lambda f: isinstance(f, Fault)).code == 3
        proc.stdin.write("status\n")
        proc.stdin.flush()
        assert json.loads(proc.stdout.readline())["state"] == "FAULT"
        host.port.close()
        proc.stdin.write("quit\n")
        proc.stdin.flush()
        assert proc.wait(10) == 0
        assert not link.exists()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)


def test_refuses_to_start_without_a_port(tmp_path):
    res = subprocess.run(
        [sys.executable, "-m", "aeb_radar_camera.tools.sim.actuator", "--port",
         str(tmp_path / "nope"), "--no-control"],
        cwd=REPO, capture_output=True, text=True, timeout=60,
    )
    assert res.returncode == 2 and "error:" in res.stderr
