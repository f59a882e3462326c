"""`aeb ab-report`: pairing two fusion instances by radar cycle, the report, recordings,
and the command live on a bus."""

import json
import subprocess
import threading

import pytest

from common.keys import FUSION_BRAKE_CMD, FUSION_TARGETS
from common.messages import Decision, Verification, encode
from tests.support import START_TIMEOUT_S, open_bus, python_module
from tests.system.messages import brake_command, target, verified_targets
from tools.ab.compare import Comparator, render
from tools.ab.recording import RecordingError, read_records, write_record


def disagrees(seq: int) -> bool:
    return 5 <= seq % 20 <= 9


def cycle(instance: str, seq: int):
    """Both instances see track 7 closing; the candidate rejects it on cycles 5-9 of 20."""
    brake = instance == "primary" or not disagrees(seq)
    verification = Verification.VERIFIED if brake else Verification.REJECTED
    decision = Decision.BRAKE if brake else Decision.NONE
    density = 0.08 if instance == "primary" else (0.08 if brake else 0.01)
    targets = (target(7, 10.0, decision, verification, density),
               target(8, 30.0, Decision.NONE, Verification.NOT_CHECKED, None, in_path=False))
    return (verified_targets(instance, seq, targets,
                             "edge_density" if instance == "primary" else "adaptive"),
            brake_command(instance, seq, seq, decision))


def test_disagreements_are_paired_by_cycle_and_grouped_into_episodes():
    comp = Comparator()
    for seq in range(40):
        # Arrival order differs between the instances and kinds.
        for instance in (("candidate", "primary") if seq % 2 else ("primary", "candidate")):
            targets, command = cycle(instance, seq)
            comp.add_command(command)
            comp.add_targets(targets)
    r = comp.report()
    assert r.cycles_compared == 40 and r.commands_compared == 40
    assert r.commands_disagreed == 10
    assert r.tracks_compared == 80 and r.tracks_disagreed == 10
    assert r.kinds == {"command: BRAKE vs NONE": 10,
                       "track: verified/BRAKE vs rejected/NONE": 10}
    assert r.verification[("verified", "rejected")] == 10
    assert r.verification[("not_checked", "not_checked")] == 40
    spans = [(e.kind.split(":")[0], e.first_seq, e.last_seq, e.cycles) for e in r.episodes]
    assert spans == [("command", 5, 9, 5), ("track", 5, 9, 5),
                     ("command", 25, 29, 5), ("track", 25, 29, 5)]
    text = render(r)
    assert "commands: 10 disagreed (75.0% agreement)" in text
    assert "density 0.080 (edge_density) vs 0.010 (adaptive)" in text


def test_cycles_only_one_instance_published_are_counted_not_compared():
    comp = Comparator()
    for seq in range(100):
        comp.add_targets(cycle("primary", seq)[0])
        if seq % 10 != 0:
            comp.add_targets(cycle("candidate", seq)[0])
    r = comp.report()
    assert r.cycles_compared == 90
    assert r.only_primary >= 5           # the older unpaired ones have expired
    assert r.only_candidate == 0
    with pytest.raises(ValueError):
        Comparator("primary", "primary")


def test_recordings_round_trip_and_damage_is_reported(tmp_path):
    path = tmp_path / "ab.rec"
    targets, command = cycle("primary", 3)
    with open(path, "wb") as f:
        write_record(f, FUSION_TARGETS.name, "k1", 1, encode(targets))
        write_record(f, FUSION_BRAKE_CMD.name, "k2", 2, encode(command))
        f.write(b"\x00\x00\x01\x00partial")      # interrupted while writing
    records = list(read_records(path))
    assert [(r[0], r[1], r[2]) for r in records] == [
        (FUSION_TARGETS.name, "k1", 1), (FUSION_BRAKE_CMD.name, "k2", 2)]
    bad = tmp_path / "bad.rec"
    bad.write_bytes(b"\x00\x00\x00\x03abc")
    with pytest.raises(RecordingError, match="byte 0"):
        list(read_records(bad))


@pytest.mark.slow
def test_ab_report_live_with_a_recording_that_reports_the_same(router, tmp_path):
    stop = threading.Event()
    rec = tmp_path / "ab.rec"
    with open_bus(router, source="fusion") as bus:
        pubs = {(spec.name, inst): bus.publisher(spec, instance=inst)
                for spec in (FUSION_TARGETS, FUSION_BRAKE_CMD)
                for inst in ("primary", "candidate")}

        def publish() -> None:
            seq = 0
            while not stop.wait(0.02):
                for inst in ("primary", "candidate"):
                    targets, command = cycle(inst, seq)
                    pubs[(FUSION_TARGETS.name, inst)].put(targets)
                    pubs[(FUSION_BRAKE_CMD.name, inst)].put(command)
                seq += 1

        thread = threading.Thread(target=publish, daemon=True)
        thread.start()
        try:
            live = subprocess.run(
                python_module("tools.cli", "ab-report", "--connect", router, "--duration", "4",
                              "--record", str(rec), "--json"),
                capture_output=True, text=True, timeout=START_TIMEOUT_S + 30)
        finally:
            stop.set()
            thread.join(5)
    assert live.returncode == 0, live.stderr
    report = json.loads(live.stdout)
    assert report["commands_compared"] >= 20
    assert set(report["kinds"]) <= {"command: BRAKE vs NONE",
                                    "track: verified/BRAKE vs rejected/NONE"}
    assert report["commands_disagreed"] > 0
    for e in report["episodes"]:
        assert disagrees(e["first_seq"]) and disagrees(e["last_seq"])
    replay = subprocess.run(python_module("tools.cli", "ab-report", "--from", str(rec),
                                          "--json"), capture_output=True, text=True, timeout=60)
    assert replay.returncode == 0, replay.stderr
    again = json.loads(replay.stdout)
    assert again["commands_disagreed"] == report["commands_disagreed"]
    assert again["episodes"] == report["episodes"]
    text = subprocess.run(python_module("tools.cli", "ab-report", "--from", str(rec)),
                          capture_output=True, text=True, timeout=60)
    assert "A/B: primary (followed by the brake) vs candidate (shadow)" in text.stdout
    missing = subprocess.run(python_module("tools.cli", "ab-report", "--from",
                                           str(tmp_path / "none.rec")),
                             capture_output=True, text=True, timeout=60)
    assert missing.returncode == 2 and "not found" in missing.stderr
