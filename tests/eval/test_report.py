"""The report's breakdowns on hand-made ROI records: per kind of negative (and its
clear-view part), per stratum, per class, and what is left out and why."""

import pytest

from tools.eval.records import FrameRef, RoiRecord, Score
from tools.eval.report import ReportSettings, evaluate, evaluate_all


def rec(i, score, kind, truth, in_view=False, cls="", lighting="day", range_m=10.0,
        verdict=None):
    return RoiRecord(id=f"r{i}", source="kitti", session="s", frame=str(i // 3), t_ns=0,
                     camera="image_2", image_w=100, image_h=100, roi=(0, 0, 10, 10),
                     column=(0, 0, 10, 10), range_m=range_m, kind=kind,
                     frame_ref=FrameRef("none", ""), obj_class=cls, truth=truth,
                     lighting=lighting, object_in_view=in_view,
                     scores={"v": Score(score, score >= 0.1 if verdict is None else verdict),
                             "depth": Score(None, None)})


RECORDS = ([rec(i, 0.2 + 0.01 * i, "object", "YES", cls="Car" if i % 2 else "Pedestrian",
                range_m=5.0 + 2 * i) for i in range(8)]
           + [rec(10 + i, 0.05 * i, "background", "NO", range_m=4.0) for i in range(6)]
           + [rec(20 + i, 0.3, "lidar", "NO", in_view=True) for i in range(3)]
           + [rec(30 + i, 0.02, "lidar", "NO", lighting="night") for i in range(3)])


def test_negative_kinds_and_the_clear_view_subset():
    labels = {r.id: r.truth for r in RECORDS}
    ev = evaluate(RECORDS, labels, "v", {"tau": 0.1}, ReportSettings(n_boot=200))
    kinds = {k["kind"]: k for k in ev["negative_kinds"]}
    assert list(kinds) == ["background", "lidar", "lidar, clear view"]
    assert kinds["lidar"]["n_no"] == 6 and kinds["lidar, clear view"]["n_no"] == 3
    # Objects score 0.20-0.27: the lidar ROIs with an object in view (0.3) beat them all.
    assert kinds["lidar"]["auc"] == pytest.approx(0.5)
    assert kinds["lidar, clear view"]["auc"] == 1.0
    assert kinds["lidar, clear view"]["pass_rate_operating"] == 0.0
    assert kinds["background"]["pass_rate_tau"] == pytest.approx(4 / 6)
    assert ev["at_tau"]["tp"] == 8 and ev["at_tau"]["fp"] == 4 + 3


def test_strata_classes_and_what_is_left_out():
    labels = {r.id: r.truth for r in RECORDS}
    labels["r0"] = "ambiguous"
    del labels["r1"]
    result = evaluate_all(RECORDS, labels, {"v": {"tau": 0.1}, "depth": {}},
                          ReportSettings(n_boot=100))
    ev = result["verifiers"]["v"]
    assert ev["counts"]["ambiguous"] == 1 and ev["counts"]["unlabelled"] == 1
    assert ev["n_yes"] == 6
    assert "depth" in result["skipped"] and "not_applicable" in result["skipped"]["depth"]
    assert [s["name"] for s in ev["strata"]["range"]] == ["3-8 m", "8-15 m", "15-25 m"]
    assert {s["name"]: s["n"] for s in ev["strata"]["lighting"]} == {"day": 15, "night": 3}
    assert {c["class"]: c["n"] for c in ev["recall_by_class"]} == {"Car": 3, "Pedestrian": 3}
    assert result["labels"] == {"YES": 6, "NO": 12, "ambiguous": 1}
