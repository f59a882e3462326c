"""An intruder on the vehicle network, default profile (plain TCP, no access control):
the brake service and a fusion-like publisher holding the instance's key, as their own
processes on loopback; the SIMULATED attacker (tools/faults/intruder.py) publishes unsigned
commands with sequence numbers ahead, 2**62, forged MACs, replays of the real commands
and a flood. Every one that reaches the brake is refused and counted (the keys are DROP:
a full queue on the way may drop some), the brake never moves, and the real fusion stays
in command."""

import json
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from aeb_radar_camera.common.messages import BrakeState, BrakeStatus
from tests.brake.rig import BrakeRig, brake_rig, received, wait_settled
from tests.brake.secure import OPENSSL
from tests.support import ServiceProcess, python_module, wait_for

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def rig(tmp_path_factory: pytest.TempPathFactory) -> Iterator[BrakeRig]:
    with brake_rig(tmp_path_factory.mktemp("intruder")) as r:
        yield r


def intruder(rig: BrakeRig, *args: str, name: str = "intruder") -> ServiceProcess:
    return ServiceProcess(name, python_module(
        "aeb_radar_camera.tools.faults.intruder", "--connect", rig.endpoint, *args), rig.log_dir)


def finished(proc: ServiceProcess, timeout_s: float = 60.0) -> dict[str, int]:
    wait_for(lambda: not proc.alive(), timeout_s, what="the intruder to finish")
    out = proc.output()
    assert proc.proc.returncode == 0, out
    sent: dict[str, int] = json.loads(out.strip().splitlines()[-1])["sent"]
    return sent


def unsigned_count(sent: dict[str, int]) -> int:
    """How many of the intruder's commands it sent without a MAC (the rest: forged)."""
    return sent["ahead"] + sent["jump"] // 2 + (sent["flood"] + 1) // 2


def intruders_refusals(s: BrakeStatus) -> int:
    """Refusals only an intruder's commands get here (a real command the loaded host
    delayed is `too_old` too)."""
    return sum(v for k, v in s.rejected.items() if k != "too_old")


def test_an_intruder_is_refused_counted_and_the_real_fusion_stays_in_command(rig):
    start = len(rig.status)
    fusion = rig.publisher(level=0.0, name="fusion")     # signs with the instance's key
    try:
        rig.wait_live(start)
        _, before = rig.wait_status(lambda s: True, len(rig.status))
        t0 = time.monotonic_ns()
        sent = finished(intruder(rig, "--flood-s", "1.0"))
        t_sent = time.monotonic_ns()
        # the key is DROP: what a full queue on the way dropped never reaches the brake,
        # so what the brake took (`command_samples`) is judged, once nothing more comes
        i, after = wait_settled(rig, intruders_refusals, t_sent, len(rig.status),
                                what="the intruder's refusals settled")
        t1 = after.header.pub_mono_ns
        # the real fusion still in command: its commands are followed after the attack
        _, later = rig.wait_status(lambda s: s.last_cmd_seq > after.last_cmd_seq + 5, i)
        statuses = rig.status.since(start)
    finally:
        fusion.stop()
    got = received(before, after)
    grew = got.refused
    total = sum(sent.values())
    print(f"\nintruder: sent {sent}; the brake took {got.samples} commands, followed "
          f"{got.followed}, refused {grew}")
    assert sent["ahead"] == 3 and sent["jump"] == 4 and sent["replay"] > 10
    assert sent["flood"] > 500          # 1 s at 1 kHz
    unsigned = unsigned_count(sent)
    forged = total - sent["replay"] - unsigned
    # every command the brake took is counted: followed (the real fusion's, signed) or
    # refused with its reason
    assert got.failed == 0 and got.samples == got.accounted, got
    assert set(grew) <= {"unauthenticated", "bad_mac", "too_old", "duplicate",
                         "old_sequence"}, grew
    # never more refusals of a kind than the intruder sent of it; most reach the brake
    assert 0 < grew.get("unauthenticated", 0) <= unsigned, (grew, unsigned)
    assert 0 < grew.get("bad_mac", 0) <= forged, (grew, forged)
    assert grew["unauthenticated"] + grew["bad_mac"] > 0.5 * (unsigned + forged), (grew, sent)
    # the replays refused (too_old, or duplicate / old_sequence when they arrive early);
    # a real command delayed beyond max_age_ms on a loaded host is too_old as well
    assert grew.get("too_old", 0) + grew.get("duplicate", 0) + grew.get(
        "old_sequence", 0) > 0.5 * sent["replay"], grew
    # no intruder's BRAKE 100 % reached the actuator; the brake followed the real fusion's
    # session throughout (no other stream taken up)
    assert set(r.cmd.level_pct for r in rig.sim.commands_since(t0)) == {0}
    for counter in ("stream_restarts", "seq_resyncs", "seq_conflicts_opened"):
        assert after.counters.get(counter, 0) == before.counters.get(counter, 0), counter
    window = [s for s in statuses if t0 <= s.header.pub_mono_ns <= t1]
    assert window and all(s.state is BrakeState.ARMED for s in window), \
        {s.state for s in window}
    assert later.state is BrakeState.ARMED and later.counters["commands"] > \
        after.counters["commands"]


def test_a_brake_without_command_keys_refuses_to_start(tmp_path: Path):
    (tmp_path / "brake.toml").write_text('[brake.serial]\nport = "/dev/null"\n')
    proc = ServiceProcess("brake-nokeys", python_module(
        "aeb_radar_camera.services.brake", "--config", str(tmp_path / "brake.toml")), tmp_path)
    wait_for(lambda: not proc.alive(), 30, what="the brake to exit")
    assert proc.proc.returncode == 2
    assert "brake.command_keys is empty" in proc.output()


@pytest.mark.skipif(not OPENSSL, reason="openssl is not installed (the default-profile "
                    "test above runs without it)")
def test_secure_profile_an_intruder_with_the_candidates_or_the_primarys_certificate(
        tmp_path: Path):
    """Secure profile: the candidate's certificate cannot publish on the primary's key
    (the router drops it, nothing reaches the brake); a process with the primary's own
    certificate but not its command key reaches the brake and is refused there."""
    with brake_rig(tmp_path, secure=True) as rig:
        assert rig.secure is not None
        start = len(rig.status)
        fusion = rig.publisher(level=0.0, name="fusion")
        try:
            rig.wait_live(start, timeout_s=60)
            _, before = rig.wait_status(lambda s: True, len(rig.status))
            t0 = time.monotonic_ns()
            common = ("--blind", "--attacks", "ahead,jump,forged,flood", "--flood-s", "0.5")
            sent_candidate = finished(intruder(
                rig, *common, "--zenoh-config", str(rig.secure.client("fusion-candidate")),
                name="intruder-candidate"))
            # the fusion's later commands went through the same router after the attack
            i, quiet = rig.wait_status(
                lambda s: s.last_cmd_seq > before.last_cmd_seq + 20, len(rig.status), 30)
            sent_stolen = finished(intruder(
                rig, *common, "--zenoh-config", str(rig.secure.client("fusion")),
                name="intruder-stolen-cert"))
            total = sum(sent_stolen.values())
            _, after = wait_settled(rig, intruders_refusals, time.monotonic_ns(), i,
                                    what="the intruder's refusals settled")
            _, later = rig.wait_status(lambda s: s.last_cmd_seq > after.last_cmd_seq + 5,
                                       len(rig.status), 30)
            t1 = time.monotonic_ns()
            statuses = rig.status.since(start)
        finally:
            fusion.stop()
    assert sum(sent_candidate.values()) > 200
    # (a real command delayed beyond max_age_ms on a loaded host is too_old: not theirs)
    assert {k: v for k, v in quiet.rejected.items() if k != "too_old"} == \
        {k: v for k, v in before.rejected.items() if k != "too_old"}, \
        "the candidate's commands reached the brake"
    got = received(before, after)
    grew = got.refused
    unsigned = unsigned_count(sent_stolen)
    # every command the brake took counted; blind: the key id is guessed too
    # (unknown_key), never a valid MAC; most of what was sent reaches the brake (the key
    # is DROP: a full queue on the way may drop some)
    assert got.failed == 0 and got.samples == got.accounted, got
    assert set(grew) <= {"unauthenticated", "unknown_key", "too_old"}, grew
    assert 0 < grew.get("unauthenticated", 0) <= unsigned, (grew, unsigned)
    assert 0 < grew.get("unknown_key", 0) <= total - unsigned, (grew, total)
    assert grew["unauthenticated"] + grew["unknown_key"] > 0.5 * total, (grew, total)
    assert set(r.cmd.level_pct for r in rig.sim.commands_since(t0)) == {0}
    window = [s for s in statuses if t0 <= s.header.pub_mono_ns <= t1]
    assert window and all(s.state is BrakeState.ARMED for s in window)
    assert later.state is BrakeState.ARMED
