"""`aeb ab-report`: pairing two fusion instances by radar cycle, the report, MCAP
recordings (and a file that is not one), and the command live on a bus."""

import json
import subprocess
import threading

import pytest

from aeb_radar_camera.common.keys import FUSION_BRAKE_CMD, FUSION_TARGETS
from aeb_radar_camera.common.messages import Decision, Verification, encode
from aeb_radar_camera.tools.ab.compare import Comparator, render
from aeb_radar_camera.tools.recording.format import channel_of_topic
from aeb_radar_camera.tools.recording.writer import RecordingWriter
from tests.support import START_TIMEOUT_S, open_bus, python_module
from tests.system.messages import brake_command, target, verified_targets


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


def ab_report(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(python_module("aeb_radar_camera.tools.cli", "ab-report", *args),
                          capture_output=True,
                          text=True, timeout=60)


def test_the_report_of_an_mcap_recording(tmp_path):
    path = tmp_path / "ab.mcap"
    with RecordingWriter(path, metadata={"vehicle": "ego"}) as w:
        t = 10**18
        for seq in range(20):
            for instance in ("primary", "candidate"):
                targets, command = cycle(instance, seq)
                for key, msg in ((FUSION_TARGETS.key("ego", instance=instance), targets),
                                 (FUSION_BRAKE_CMD.key("ego", instance=instance), command)):
                    t += 1000
                    w.write(key, channel_of_topic(key), encode(msg), t, t)
    proc = ab_report("--from", str(path), "--json")
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report["commands_compared"] == 20 and report["commands_disagreed"] == 5


def test_a_file_that_is_not_a_recording_is_said_so_and_fails(tmp_path):
    """A file that is not a recording fails with a message naming it, never "no
    disagreement" and exit 0."""
    notes = tmp_path / "notes.txt"
    notes.write_text("primary and candidate agreed on everything, I think\n")
    proc = ab_report("--from", str(notes))
    assert proc.returncode == 2
    assert f"{notes} is not an MCAP recording" in proc.stderr
    assert "no disagreement" not in proc.stdout
    # A recording, but without the candidate's outputs: nothing to compare is no report.
    path = tmp_path / "primary-only.mcap"
    with RecordingWriter(path) as w:
        key = FUSION_BRAKE_CMD.key("ego", instance="primary")
        w.write(key, channel_of_topic(key), encode(cycle("primary", 0)[1]), 1, 1)
    proc = ab_report("--from", str(path))
    assert proc.returncode == 2 and "no output of fusion instance 'candidate'" in proc.stderr
    missing = ab_report("--from", str(tmp_path / "none.mcap"))
    assert missing.returncode == 2 and "no such file" in missing.stderr


@pytest.mark.slow
def test_ab_report_live_with_a_recording_that_reports_the_same(router, tmp_path):
    stop = threading.Event()
    rec = tmp_path / "ab.mcap"
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
                python_module("aeb_radar_camera.tools.cli", "ab-report", "--connect", router,
                              "--duration", "4",
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
    replay = subprocess.run(python_module("aeb_radar_camera.tools.cli", "ab-report", "--from",
                                          str(rec),
                                          "--json"), capture_output=True, text=True, timeout=60)
    assert replay.returncode == 0, replay.stderr
    again = json.loads(replay.stdout)
    assert again["commands_disagreed"] == report["commands_disagreed"]
    assert again["episodes"] == report["episodes"]
    text = subprocess.run(python_module("aeb_radar_camera.tools.cli", "ab-report", "--from",
                                        str(rec)),
                          capture_output=True, text=True, timeout=60)
    assert "A/B: primary (followed by the brake) vs candidate (shadow)" in text.stdout

