"""`aeb demo` recorded with `aeb record` (beside it, as a separate process), the file
opened as a generic tool opens it: every key of the stack present, every message decoding
with its channel's schema, the frame, annotation and scene channels valid for Foxglove's
schemas; and the evidence folder of the BRAKE, written by the recorder.

The same checks run on the simulator recording kept in tests/data/recording/ (fast), and
on a fresh demo run (slow)."""

import json
import subprocess

import cv2
import numpy as np
import pytest

from aeb_radar_camera.common.net import free_port
from aeb_radar_camera.tools.recording.evidence_frames import contrast
from aeb_radar_camera.tools.recording.format import parse_topic
from tests.recording.checks import STACK_SPECS, check_recording, stamp_ns
from tests.support import REPO, ServiceProcess, python_module

SIM = REPO / "tests" / "data" / "recording" / "pedestrian_standing_20kph.mcap"


def check_stack_recording(path):
    found = check_recording(path)
    channels = found["channels"]
    specs = {info.spec.name for t in channels if (info := parse_topic(t)) is not None}
    assert specs >= STACK_SPECS, STACK_SPECS - specs
    views = found["views"]
    images = views["foxglove.CompressedImage"]
    assert all(im.format == "jpeg" and im.data[:2] == b"\xff\xd8" for im in images)
    image_stamps = {stamp_ns(im.timestamp) for im in images}
    anns = views["foxglove.ImageAnnotations"]
    assert anns
    for a in anns:
        assert len(a.points) == len(a.texts) >= 1
        for box in a.points:
            assert len(box.points) == 4
            # The ROI is drawn on the frame it was checked in.
            assert stamp_ns(box.timestamp) in image_stamps
    scenes = views["foxglove.SceneUpdate"]
    assert any(e.id == "corridor" for s in scenes for e in s.entities)
    assert any(e.id.startswith("track-") and e.cubes for s in scenes for e in s.entities)
    return found


def test_the_kept_simulator_recording_is_whole_and_valid_for_foxglove():
    found = check_stack_recording(SIM)
    assert found["channels"]["aeb/ego/fusion/primary/brake_cmd"] == ("aeb.BrakeCommand", 83)


def test_evidence_of_the_warning_and_the_brake(tmp_path):
    proc = subprocess.run(python_module("aeb_radar_camera.tools.cli", "evidence", "--from",
                                        str(SIM), "--out",
                                        str(tmp_path), "--fusion-config",
                                        "deploy/fusion.toml"),
                          capture_output=True, text=True, timeout=120, cwd=REPO)
    assert proc.returncode == 0, proc.stderr
    folders = sorted(p for p in tmp_path.iterdir() if p.is_dir())
    assert [f.name.split("_")[2] for f in folders] == ["WARNING", "BRAKE"]
    brake = folders[1]
    files = {p.name for p in brake.iterdir()}
    assert {"README.md", "event.json", "command.json", "targets.json", "tracks.json",
            "history.json", "history.png", "frame.jpg", "frame_annotated.jpg", "roi.png",
            "can.log", "brake_status.json"} <= files
    # The Canny edges are shown for the edge-density verifiers only (the shipped one is
    # `combined`).
    assert "roi_edges.png" not in files
    event = json.loads((brake / "event.json").read_text())
    t = event["track"]
    assert event["decision"] == "BRAKE" and t["verification"] == "verified"
    assert t["density"] >= t["threshold"] == 1.0          # combined: its score, its tau
    assert t["ttc_eff_s"] < event["thresholds"]["brake_ttc_eff_s"]
    assert event["corridor"]["in_path"] and event["can_frames"] > 0
    stages = [s["stage"] for s in event["stages"]]
    assert stages[0] == "radar: last CAN frame of the cycle"
    assert "brake: command bytes on the serial line" in stages
    readme = (brake / "README.md").read_text()
    # the score named for what it is: the verifier's, not an edge density
    assert "**Why:** track" in readme and "| combined score | 1.5" in readme
    assert "| density |" not in readme
    # the deciding ROI's label readable at a glance: on a box of its colour, text in
    # black or white whichever contrasts, about 15 px high on the 480-line frame
    img = cv2.imread(str(brake / "frame_annotated.jpg"))
    x, y = t["roi_xywh"][:2]
    box = _label_box_above(img, x, y)
    assert box is not None, "no label box above the deciding ROI"
    colour, height, text = box
    assert height >= 18 and contrast(colour, text) >= 4.5
    import can

    frames = list(can.LogReader(str(brake / "can.log")))
    assert len(frames) == event["can_frames"]
    history = json.loads((brake / "history.json").read_text())
    assert len(history) >= 3 and history[-1]["t_s"] == 0.0


@pytest.mark.slow
def test_a_demo_run_recorded_beside_it(tmp_path):
    port = free_port()
    out = tmp_path / "demo.mcap"
    recorder = ServiceProcess("record", python_module(
        "aeb_radar_camera.tools.cli", "record", "-o", str(out), "--connect",
        f"tcp/127.0.0.1:{port}",
        "--evidence", str(tmp_path / "evidence"), "--fusion-config", "deploy/fusion.toml"),
        tmp_path)
    try:
        demo = subprocess.run(python_module(
            "aeb_radar_camera.tools.cli", "demo", "--scenarios", "stationary_car_30kph", "--port",
            str(port),
            "--raw-can", "--out", str(tmp_path / "demo")),
            capture_output=True, text=True, timeout=600, cwd=REPO)
        assert demo.returncode == 0, demo.stdout[-3000:] + demo.stderr[-3000:]
    finally:
        assert recorder.stop() == 0, recorder.output()
    check_stack_recording(out)
    brakes = [p for p in (tmp_path / "evidence").iterdir() if "_BRAKE_" in p.name]
    assert brakes and (brakes[0] / "frame_annotated.jpg").is_file()
    # The radar's re-run on the demo's raw CAN reproduces its tracks; fusion's decisions.
    radar = subprocess.run(python_module("aeb_radar_camera.tools.cli", "rerun", "radar", str(out),
                                         "--compare",
                                         "--quiet"),
                           capture_output=True, text=True, timeout=120, cwd=REPO)
    assert radar.returncode == 0 and "with a difference: 0" in radar.stdout, radar.stdout
    fusion = subprocess.run(python_module("aeb_radar_camera.tools.cli", "rerun", "fusion",
                                          str(out), "--compare",
                                          "--quiet", "--json", str(tmp_path / "f.json")),
                            capture_output=True, text=True, timeout=120, cwd=REPO)
    fields = json.loads((tmp_path / "f.json").read_text())["comparison"]["fields"]
    assert not any(k.startswith(("decisions.", "commands.decision")) for k in fields), \
        fusion.stdout


def _label_box_above(img, x: int, y: int):
    """(box colour, box height, text colour) of the filled label box right above a ROI
    whose top-left corner is (x, y), or None. The box's left padding has no text: its
    height is the run of rows of one colour there."""
    colour = img[y - 3, x + 2].astype(int)
    height = 0
    while y - 1 - height >= 0 and np.abs(img[y - 1 - height, x + 1:x + 3].astype(int)
                                         - colour).sum(axis=1).max() < 60:
        height += 1
    if height < 2:
        return None
    region = img[y - height:y, x:x + 200].reshape(-1, 3).astype(int)
    far = region[np.abs(region - colour).sum(axis=1) > 250]
    if len(far) < 20:
        return None
    text = np.median(far, axis=0)
    return tuple(int(c) for c in colour), height, tuple(int(c) for c in text)
