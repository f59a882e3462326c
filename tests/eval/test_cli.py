"""`aeb eval` end to end on generated inputs: ROIs from a recording and a KITTI folder in
parallel processes, the report's tables, JSON and plots, comparison, and bad input."""

import json

import pytest

from aeb_radar_camera.tools.cli import main as aeb
from aeb_radar_camera.tools.eval.records import read_records
from aeb_radar_camera.tools.eval.scoring import default_specs
from tests.eval.fixtures import write_kitti, write_sim_recording


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    root = tmp_path_factory.mktemp("inputs")
    return write_sim_recording(root / "drive.mcap").path, write_kitti(root / "kitti", 3)


def test_run_on_a_recording_and_a_data_set_in_two_processes(inputs, tmp_path, capsys):
    recording, kitti = inputs
    out = tmp_path / "eval"
    code = aeb(["eval", "run", str(recording), str(kitti), "--out", str(out), "--jobs", "2",
                "--frames-per-task", "1", "--boot", "200"])
    text = capsys.readouterr()
    assert code == 0, text.err
    assert "4 tasks on 2 local processes" in text.err and "4/4 tasks" in text.err
    records = read_records(out)
    assert {r.source for r in records} == {"recording", "kitti"}
    # Background ROIs on the fixture's unlabelled wall hold lidar standing at their range.
    assert {r.kind for r in records} == {"track", "background", "background_standing",
                                         "object", "lidar"}
    run = json.loads((out / "run.json").read_text())
    assert run["workers"] == 2 and run["counters"]["frames"] == 3
    assert set(run["verifiers"]) == {s.name for s in default_specs()}
    assert (out / "truth-labels.tsv").read_text().count("\tYES\t") == sum(
        r.truth == "YES" for r in records)
    report = json.loads((out / "report.json").read_text())
    ev = report["verifiers"]["edge_density"]
    # Real structures (the lidar ROIs, background on the wall) are reported apart, not
    # as negatives.
    assert ev["n"] + ev["real_structure"]["n"] == len(records)
    assert ev["real_structure"]["n"] == sum(r.kind in ("lidar", "background_standing")
                                            for r in records)
    assert ev["ci"][0] <= ev["auc"] <= ev["ci"][1]
    # The negatives named for what stands there: the ghost track and the background ROIs
    # are empty scene, the lidar ROIs and the background on the wall real structures.
    kinds = {k["kind"]: k for k in ev["negative_kinds"]}
    assert set(kinds) == {"empty scene", "real structure"}
    assert set(kinds["empty scene"]["members"]) == {"background", "track on no object"}
    assert set(kinds["real structure"]["members"]) == {
        "lidar structure", "background, lidar standing at its range"}
    assert "real structures (background, lidar standing at its range 1, lidar structure 3" \
        in text.out
    assert "Table III: edge_density" in text.out and "Table II" in text.out
    for png in ("roc.png", "confusion.png", "density.png", "timing.png"):
        assert (out / png).read_bytes()[:4] == b"\x89PNG"


def test_compare_and_report_from_a_stored_set(inputs, tmp_path, capsys):
    recording, _ = inputs
    out = tmp_path / "eval"
    assert aeb(["eval", "rois", str(recording), "--out", str(out), "--jobs", "1",
                "--verifier", "edge_density", "--verifier", "edge_density:tau=0.08"]) == 0
    capsys.readouterr()
    assert aeb(["eval", "compare", str(out), "--boot", "100", "--no-plots"]) == 0
    text = capsys.readouterr().out
    assert "| edge_density |" in text and "| edge_density:tau=0.08 |" in text
    compare = json.loads((out / "compare.json").read_text())
    a, b = (compare["verifiers"][k] for k in ("edge_density", "edge_density:tau=0.08"))
    assert a["auc"] == b["auc"]                           # same scores, other threshold
    assert a["operating"]["recall"] >= b["operating"]["recall"]
    assert aeb(["eval", "report", str(out), "--only", "edge_density", "--tau", "0.05",
                "--boot", "100", "--no-plots"]) == 0
    assert "Deployed (τ=0.050)" in capsys.readouterr().out


def test_bad_sources_are_errors_and_a_bad_recording_does_not_stop_the_others(inputs, tmp_path,
                                                                             capsys):
    recording, _ = inputs
    assert aeb(["eval", "rois", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    assert "no such recording" in capsys.readouterr().err
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"garbage")
    code = aeb(["eval", "rois", str(recording), str(bad), "--out", str(tmp_path / "o"),
                "--jobs", "1"])
    err = capsys.readouterr().err
    assert code == 1 and "bad.mcap is not an MCAP recording" in err
    assert read_records(tmp_path / "o")
    assert aeb(["eval", "rois", str(recording), "--out", str(tmp_path / "p"),
                "--verifier", "nope"]) == 2
    assert "unknown verifier 'nope'" in capsys.readouterr().err
    assert aeb(["label", str(tmp_path / "o"), "--labels", str(tmp_path / "l.tsv")]) == 2
    assert "every ROI has ground truth" in capsys.readouterr().err


def test_record_demo_records_a_closed_loop_run_that_eval_reads(tmp_path, capsys):
    out = tmp_path / "demo.mcap"
    assert aeb(["eval", "record-demo", "--out", str(out),
                "--scenarios", "pedestrian_standing_20kph"]) == 0
    printed = capsys.readouterr().out
    assert "aeb/ego/sim/world:" in printed and "aeb/ego/camera/front/jpeg:" in printed
    assert aeb(["eval", "rois", str(out), "--out", str(tmp_path / "rois"), "--jobs", "1"]) == 0
    records = read_records(tmp_path / "rois")
    assert any(r.truth == "YES" for r in records)
