"""The brake service as its own process: a router,
the simulated actuator on a pty, commands over Zenoh, bytes checked on the line."""

import os
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from aeb_radar_camera.common.keys import FUSION_BRAKE_CMD
from aeb_radar_camera.common.messages import BrakeState, encode
from aeb_radar_camera.services.brake.commands import RECENT
from aeb_radar_camera.services.brake.protocol import HostMode
from aeb_radar_camera.tools.sim.actuator import SimActuator
from tests.brake.helpers import command, write_test_key
from tests.brake.rig import BrakeRig, Stream, brake_rig
from tests.support import (
    HealthWatch,
    ServiceProcess,
    free_port,
    open_bus,
    python_module,
    router_process,
    wait_for,
)

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def rig(tmp_path_factory: pytest.TempPathFactory) -> Iterator[BrakeRig]:
    with brake_rig(tmp_path_factory.mktemp("brake"), min_brake_hold_ms=100.0,
                   failsafe_hold_s=0.5) as r:
        yield r


def _levels_since(rig: BrakeRig, t_ns: int) -> list[int]:
    return [r.cmd.level_pct for r in rig.sim.commands_since(t_ns)]


def test_brake_command_puts_brake_bytes_on_the_line(rig):
    """A BRAKE command: its level on the actuator line, mode B."""
    start = len(rig.status)
    with Stream(rig.bus) as stream:
        rig.wait_live(start, since_ns=stream.started_ns)
        t_brake = time.monotonic_ns()
        stream.level = 70.0
        found = wait_for(lambda: [r for r in rig.sim.commands_since(t_brake)
                                  if r.cmd.level_pct == 70], 10, what="level 70")
        line = found[0]
        first = next(m for m in stream.sent if m.brake_level_pct == 70.0)
        assert line.t_ns > first.header.pub_mono_ns
        assert line.cmd.mode is HostMode.BRAKING
        _, status = rig.wait_status(lambda s: s.last_cmd_seq >= first.header.seq
                                    and s.state is BrakeState.BRAKING, start)
        stream.level = 0.0
    assert status.commanded_level_pct == 70.0
    assert status.cmd_to_serial_us is not None and 0 < status.cmd_to_serial_us < 1e6
    assert status.radar_to_serial_us is not None and status.radar_to_serial_us > 0
    print(f"\ncommand publish -> actuator read: {(line.t_ns - first.header.pub_mono_ns) / 1e3:.0f}"
          f" us; receipt -> serial write (service): {status.cmd_to_serial_us:.0f} us")


def test_every_rejection_reason_is_counted_and_never_moves_the_brake(rig):
    """Wrong instance (a real candidate process and a forged payload), old
    sequence, duplicate, too old, malformed, out-of-contract; the line stays at 0. (A new
    command at a sequence number already used is a second sender: tests/security.)"""
    start = len(rig.status)
    before = None
    with Stream(rig.bus) as stream:
        rig.wait_live(start, since_ns=stream.started_ns)
        # old_sequence: further behind than the accepted commands the brake remembers
        rig.wait_status(lambda s: s.last_cmd_seq > RECENT + 10, len(rig.status), 60)
        _, before = rig.wait_status(lambda s: True, len(rig.status))
        t0 = time.monotonic_ns()
        candidate = rig.publisher(level=100.0, instance="candidate", name="candidate")
        raw_key = FUSION_BRAKE_CMD.key("ego", instance="primary")

        def forged(next_seq: int) -> None:
            last = next_seq - 1
            put = stream.put
            put(stream.sent[-1])                          # duplicate (the same bytes)
            put(command(last - RECENT - 5, 100.0))        # old sequence
            put(command(next_seq, 100.0,
                        pub_mono_ns=time.monotonic_ns() - 1_000_000_000))  # too old
            put(command(next_seq, 100.0, instance="candidate"))         # wrong instance
            put(command(next_seq, 150.0))                                # out of contract
            rig.bus.session.put(raw_key, b"\x00 not a command")         # malformed
            rig.bus.session.put(raw_key, encode(command(next_seq, 100.0))[:-4])

        for _ in range(3):
            stream.inject(forged)
        # Every key is congestion control DROP: a forged sample may be dropped on the way,
        # so each reason must be counted at least once and never more than it was sent;
        # the brake's own count of the samples it handled says nothing went uncounted.
        sent = {"duplicate": 3, "old_sequence": 3, "too_old": 3, "invalid": 3,
                "malformed": 6}
        _, after = rig.wait_status(
            lambda s: all(s.rejected.get(k, 0) > before.rejected.get(k, 0) for k in sent)
            and s.rejected.get("wrong_instance", 0) >= before.rejected.get(
                "wrong_instance", 0) + 10,
            len(rig.status), 30, "every rejection reason counted")
        candidate.stop()
        t1 = time.monotonic_ns()
        statuses = rig.status.since(start)
    grew = {k: after.rejected.get(k, 0) - before.rejected.get(k, 0) for k in after.rejected}
    assert all(1 <= grew[k] <= n for k, n in sent.items()), grew
    assert grew["wrong_instance"] >= 10                  # the candidate process (+ forged)
    handled = after.counters["command_samples"] - before.counters["command_samples"]
    followed = after.counters["commands"] - before.counters["commands"]
    assert handled == followed + sum(grew.values()), (handled, followed, grew)
    assert set(_levels_since(rig, t0)) == {0}, "a rejected command moved the brake"
    window = [s for s in statuses if t0 <= s.header.pub_mono_ns <= t1]
    assert window and all(s.state is BrakeState.ARMED and s.commanded_level_pct == 0
                          for s in window)


def _hold_pty_name(name: str) -> list[int]:
    """Open ptys until the old number `name` is held, so that the reconnect cannot be
    given it back: the kernel hands out the lowest free number, and another test's pty
    closed meanwhile can make that lower than the old one. Stops at the first number
    past the old (then something else holds it). Returns the fds to close."""
    old = int(Path(name).name)
    fds: list[int] = []
    while True:
        master, slave = os.openpty()
        fds += [master, slave]
        if int(Path(os.ttyname(slave)).name) >= old:
            return fds


def test_pty_closed_and_recreated_reconnects_and_brakes_again(rig):
    """The port vanishes (EIO) and comes back under another /dev/pts name
    behind the configured path; the service reopens it by itself."""
    start = len(rig.status)
    with Stream(rig.bus, level=50.0) as stream:
        rig.wait_live(start, 50.0, since_ns=stream.started_ns)
        old_name = rig.pair.slave_name
        rig.sim.disconnect()
        i, lost = rig.wait_status(lambda s: not s.actuator_connected, start, 10, "port lost")
        assert lost.state is BrakeState.FAULT and "serial port lost" in lost.reason
        assert lost.command_state is BrakeState.BRAKING   # the decision is not forgotten
        blockers = _hold_pty_name(old_name)
        try:
            t_back = time.monotonic_ns()
            rig.sim.reconnect()
        finally:
            for fd in blockers:
                os.close(fd)
        assert rig.pair.slave_name != old_name
        rig.wait_live(i, 50.0)
        assert 50 in _levels_since(rig, t_back)
        _, st = rig.wait_status(lambda s: s.actuator_connected, i)
        stream.level = 0.0
    assert st.counters["serial_losses"] >= 1 and st.counters["serial_connects"] >= 2


def test_garbage_on_the_line_never_crashes_and_never_acknowledges(rig):
    """On the live service: random bytes, cut-short and corrupted lines
    between the acknowledgements, then garbage alone (no acknowledgements at all)."""
    start = len(rig.status)
    stop = threading.Event()

    def pump() -> None:
        while not stop.is_set():
            rig.sim.inject_garbage(40)
            stop.wait(0.005)

    pumper = threading.Thread(target=pump, daemon=True)
    with Stream(rig.bus) as stream:
        rig.wait_live(start, since_ns=stream.started_ns)
        rig.sim.set_noise(1.0)
        pumper.start()
        try:
            t_noise = time.monotonic_ns()
            i, st = rig.wait_status(
                lambda s: s.header.pub_mono_ns > t_noise + 1_000_000_000, start, 20)
            # a second of garbage between good acknowledgements: still healthy
            window = [s for s in rig.status.since(start) if s.header.pub_mono_ns > t_noise]
            assert all(s.state is BrakeState.ARMED for s in window), window[-1].reason
            bad = sum(v for k, v in st.counters.items() if k.startswith("rx_"))
            assert bad > 50
            rig.sim.set_no_ack(True)
            i, fault = rig.wait_status(lambda s: s.state is BrakeState.FAULT, i, 10)
            assert "acknowledgement" in fault.reason
            acks = fault.counters["acks"]
            t_fault = time.monotonic_ns()
            i, later = rig.wait_status(
                lambda s: s.header.pub_mono_ns > t_fault + 500_000_000, i, 10)
            assert later.counters["acks"] == acks, "garbage counted as an acknowledgement"
            assert later.state is BrakeState.FAULT
        finally:
            stop.set()
            pumper.join(5)
            rig.sim.set_noise(0.0)
            rig.sim.set_no_ack(False)
        rig.wait_live(i)
        assert stream.seq > 0
    assert rig.brake.alive()


def test_actuator_fault_line_is_fault_until_it_clears(rig):
    start = len(rig.status)
    with Stream(rig.bus) as stream:
        rig.wait_live(start, since_ns=stream.started_ns)
        rig.sim.raise_fault(3, "motor overcurrent")
        i, st = rig.wait_status(lambda s: s.state is BrakeState.FAULT, start, 10)
        assert "3: motor overcurrent" in st.reason
        rig.wait_status(lambda s: s.actuator_state == "FAULT", i, 10)
        rig.sim.clear_fault()
        rig.wait_live(i)


def test_silence_from_the_start_is_failsafe_even_without_a_router(tmp_path: Path):
    """The timer and the actuator run before Zenoh is reachable: the actuator is told
    FAILSAFE; once a router appears the service serves and recovers on commands."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    link = tmp_path / "actuator"
    sim, pair = SimActuator.on_pty(link)
    (tmp_path / "brake.toml").write_text(
        f'[brake]\ncommand_keys = ["{write_test_key(tmp_path)}"]\n'
        f'[brake.serial]\nport = "{link}"\n')
    proc = ServiceProcess("brake", python_module("aeb_radar_camera.services.brake", "--config",
                                                 str(tmp_path / "brake.toml"),
                                                 "--connect", endpoint), tmp_path)
    try:
        with sim:
            wait_for(lambda: sim.snapshot().mode == HostMode.FAILSAFE.value, 30,
                     what="FAILSAFE on the line")
            assert sim.snapshot().warning
            with router_process(tmp_path, port), open_bus(endpoint) as bus:
                HealthWatch(bus).wait_alive("brake", "main", 30)
                with Stream(bus):
                    wait_for(lambda: sim.snapshot().mode == HostMode.ARMED.value, 30,
                             what="ARMED on the line")
    finally:
        proc.stop()
        pair.remove()
    assert "since start" in proc.log_path.read_text()


def test_every_accepted_command_gets_its_own_status_soon_after(rig):
    """BrakeStatus on every change of the last sequence, not only at 10 Hz. A
    plain command's status goes out when the actuator acknowledges its line (not at a
    tick): each sequence of a 75 ms stream (the radar's rhythm), within a few ms."""
    start = len(rig.status)
    with Stream(rig.bus, period_ms=75.0) as stream:
        rig.wait_live(start, since_ns=stream.started_ns)
        wait_for(lambda: len(stream.sent) >= 30, 30, what="30 commands")
    statuses = [s for _, s in rig.status.items[start:]]
    sent = {m.header.seq for m in stream.sent}
    seen = {s.last_cmd_seq for s in statuses}
    settled = sorted(sent)[3:-2]   # the stream's first and last commands race the window
    missing = [q for q in settled if q not in seen]
    assert not missing, f"sequences without their own status: {missing}"
    # Each sequence's own status is its first: the 10 Hz ticks repeat it later.
    first: dict[int, float] = {}
    for st in statuses:
        if st.last_cmd_seq in settled and st.last_cmd_rx_mono_ns > 0:
            delay = (st.header.pub_mono_ns - st.last_cmd_rx_mono_ns) / 1e6
            first[st.last_cmd_seq] = min(delay, first.get(st.last_cmd_seq, delay))
    delays_ms = sorted(first.values())
    median = delays_ms[len(delays_ms) // 2]
    # the actuator's acknowledgement: far below the timer's 50 ms period
    assert 0 < median < 25.0, delays_ms
    print(f"\nstatus after a command: median {median:.1f} ms, max {delays_ms[-1]:.1f} ms")


def test_a_brake_killed_mid_stop_and_restarted_never_releases_the_actuator(rig):
    """SIGKILL while braking at 100 %, a new process on the same port: its first line
    holds the level the actuator held (it asks first), never `E 0`, while the command
    stream still says BRAKE."""
    start = len(rig.status)
    with Stream(rig.bus, level=100.0) as stream:
        rig.wait_live(start, 100.0, since_ns=stream.started_ns)
        rig.brake.signal(signal.SIGKILL)
        rig.brake.proc.wait(timeout=30)
        t_restart = time.monotonic_ns()
        rig.brake = ServiceProcess("brake-restarted", rig.brake.argv, rig.log_dir)
        i = len(rig.status)
        rig.wait_status(lambda s: s.state is BrakeState.BRAKING, i, 60.0, "braking again")
        levels = _levels_since(rig, t_restart)
    assert levels and min(levels) == 100, f"released after the restart: {levels[:10]}"
    assert rig.sim.queries >= 1
