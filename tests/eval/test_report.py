"""The report's breakdowns on hand-made ROI records: per kind of negative named for what
it is (and its clear-view part), real structures apart, the sweep over each verifier's
own score range, warnings on sets too small for their intervals, per stratum, per class,
and what is left out and why."""

import msgspec
import pytest

from aeb_radar_camera.tools.eval import tables
from aeb_radar_camera.tools.eval.options import PAPER_SWEEP
from aeb_radar_camera.tools.eval.records import FrameRef, RoiRecord, Score
from aeb_radar_camera.tools.eval.report import (
    ReportSettings,
    evaluate,
    evaluate_all,
    negative_category,
)


def rec(i, score, kind, truth, in_view=False, cls="", lighting="day", range_m=10.0,
        verdict=None, name="v"):
    return RoiRecord(id=f"r{i}", source="kitti", session="s", frame=str(i // 3), t_ns=0,
                     camera="image_2", image_w=100, image_h=100, roi=(0, 0, 10, 10),
                     column=(0, 0, 10, 10), range_m=range_m, kind=kind,
                     frame_ref=FrameRef("none", ""), obj_class=cls, truth=truth,
                     lighting=lighting, object_in_view=in_view,
                     scores={name: Score(score, score >= 0.1 if verdict is None else verdict),
                             "depth": Score(None, None)})


RECORDS = ([rec(i, 0.2 + 0.01 * i, "object", "YES", cls="Car" if i % 2 else "Pedestrian",
                range_m=5.0 + 2 * i) for i in range(8)]
           + [rec(10 + i, 0.05 * i, "background", "NO", range_m=4.0) for i in range(6)]
           + [rec(20 + i, 0.3, "lidar", "NO", in_view=True) for i in range(3)]
           + [rec(30 + i, 0.02, "lidar", "NO", lighting="night") for i in range(3)])


def test_negative_kinds_named_for_what_they_are_and_the_clear_view_subset():
    labels = {r.id: r.truth for r in RECORDS}
    ev = evaluate(RECORDS, labels, "v", {"tau": 0.1}, ReportSettings(n_boot=200))
    kinds = {k["kind"]: k for k in ev["negative_kinds"]}
    assert list(kinds) == ["empty scene", "real structure", "real structure, clear view"]
    assert kinds["empty scene"]["members"] == {"background": 6}
    assert kinds["real structure"]["members"] == {"lidar structure": 6}
    assert kinds["real structure"]["real_structure"] and not kinds["empty scene"][
        "real_structure"]
    assert kinds["real structure"]["n_no"] == 6
    assert kinds["real structure, clear view"]["n_no"] == 3
    # Objects score 0.20-0.27: the lidar ROIs with an object in view (0.3) beat them all.
    assert kinds["real structure"]["auc"] == pytest.approx(0.5)
    assert kinds["real structure, clear view"]["auc"] == 1.0
    assert kinds["real structure, clear view"]["pass_rate_operating"] == 0.0
    assert kinds["empty scene"]["pass_rate_tau"] == pytest.approx(4 / 6)
    # Real structures are not false passes: the headline counts the background only...
    assert ev["at_tau"]["tp"] == 8 and ev["at_tau"]["fp"] == 4 and ev["n_no"] == 6
    # ...and says how many structures it confirmed (3 of the 6 pass).
    st = ev["real_structure"]
    assert st["n"] == 6 and st["members"] == {"lidar structure": 6}
    assert st["confirmed_tau"] == pytest.approx(0.5)
    text = tables.negative_kinds_table(ev)
    assert "real structure (lidar structure 6): passing = confirmed" in text
    assert "empty scene (background 6)" in text
    assert "not counted as negatives" in tables.compare_table([ev])
    # As figures before did, on request: structures as negatives, their passes false.
    old = evaluate(RECORDS, labels, "v", {"tau": 0.1},
                   ReportSettings(n_boot=200, structures_as_negatives=True))
    assert old["at_tau"]["fp"] == 4 + 3 and old["n_no"] == 12


def test_simulator_false_targets_and_radar_returns_by_what_they_are():
    def track(cls, truth="NO"):
        return RoiRecord(id="t", source="recording", session="s", frame="0", t_ns=0,
                         camera="front", image_w=1, image_h=1, roi=(0, 0, 1, 1),
                         column=(0, 0, 1, 1), range_m=10.0, kind="track",
                         frame_ref=FrameRef("none", ""), obj_class=cls, truth=truth)

    assert negative_category(track("plate")) == "flat"
    assert negative_category(track("sign")) == "overhead"
    assert negative_category(track("guard_rail")) == "real structure"
    assert negative_category(track("ghost")) == "empty scene"
    assert negative_category(track("")) == "empty scene"         # on no object at all
    assert negative_category(track("", truth=None)) == "labelled NO"   # a person's NO
    assert negative_category(rec(0, 0.1, "radar", "NO")) == "real structure"
    assert negative_category(rec(0, 0.1, "background", "NO")) == "empty scene"
    # A background ROI with lidar standing at its range is what stands there.
    assert negative_category(rec(0, 0.1, "background_standing", "NO")) == "real structure"


def test_the_sweep_runs_over_each_verifiers_own_score_range():
    # A verifier whose scores are probabilities near 0.6-0.99: the paper's edge-density
    # thresholds (0.010-0.150) would pass everything at every row.
    yes = [rec(i, 0.90 + 0.004 * i, "object", "YES", name="combined") for i in range(20)]
    no = [rec(100 + i, 0.60 + 0.01 * i, "background", "NO", name="combined")
          for i in range(20)]
    records = yes + no
    labels = {r.id: r.truth for r in records}
    ev = evaluate(records, labels, "combined", {"tau": 0.5}, ReportSettings(n_boot=50))
    taus = [row["tau"] for row in ev["sweep"]]
    assert 0.5 in taus and min(t for t in taus if t != 0.5) >= 0.9
    # Rows keep about 99 %, 95 %, ..., 10 % of the obstacles: recall falls along them.
    recalls = [row["recall"] for row in ev["sweep"] if row["tau"] >= 0.9]
    assert recalls == sorted(recalls, reverse=True) and recalls[0] == 1.0
    assert recalls[-1] < 0.2
    assert any(row["fpr"] == 0.0 and row["recall"] == 1.0 for row in ev["sweep"])
    assert "own score range" in ev["sweep_basis"]
    assert "own score range" in tables.table_iv(ev) and "| 0.500 |" in tables.table_iv(ev)
    # An edge density keeps the paper's thresholds; --taus applies to every verifier.
    dens = [rec(i, 0.05 * (i % 5), "object" if i % 2 else "background",
                "YES" if i % 2 else "NO", name="edge_density:tau=0.08") for i in range(20)]
    ev = evaluate(dens, {r.id: r.truth for r in dens}, "edge_density:tau=0.08", {"tau": 0.08},
                  ReportSettings(n_boot=50))
    assert tuple(row["tau"] for row in ev["sweep"]) == PAPER_SWEEP
    # A verifier of any name whose score says it is an edge density: the paper's too.
    named = [msgspec.structs.replace(r, scores={"my_gate": Score(
        r.scores["edge_density:tau=0.08"].score, True, 1.0, "edge_density")}) for r in dens]
    ev = evaluate(named, {r.id: r.truth for r in named}, "my_gate", {},
                  ReportSettings(n_boot=50))
    assert tuple(row["tau"] for row in ev["sweep"]) == PAPER_SWEEP
    assert ev["score_name"] == "edge_density"
    ev = evaluate(records, labels, "combined", {"tau": 0.5},
                  ReportSettings(n_boot=50, taus=(0.2, 0.95)))
    assert [row["tau"] for row in ev["sweep"]] == [0.2, 0.95]
    assert ev["sweep"][0]["fpr"] == 1.0 and ev["sweep"][1]["fpr"] == 0.0


def test_a_set_too_small_for_its_interval_is_warned_about(capsys):
    # Three frames, one negative: the interval collapses to 0.000 [0.000, 0.000].
    records = [rec(0, 0.05, "object", "YES"), rec(1, 0.06, "object", "YES"),
               rec(2, 0.5, "background", "NO")]
    labels = {r.id: r.truth for r in records}
    result = evaluate_all(records, labels, {"v": {"tau": 0.1}}, ReportSettings(n_boot=100))
    ev = result["verifiers"]["v"]
    assert ev["auc"] == 0.0 and ev["ci"] == [0.0, 0.0]
    assert ev["few"] and "2 YES and 1 NO" in ev["few"]
    text = tables.full_report(result)
    assert text.startswith("warning: v: AUC: only 2 YES and 1 NO")
    assert "0.000 [0.000, 0.000] (too few)" in tables.compare_table([ev])
    assert any("vs empty scene" in w for w in ev["warnings"])
    # Enough of both, over enough frames: no warning.
    big = ([rec(i, 0.2 + 0.01 * i, "object", "YES") for i in range(30)]
           + [rec(100 + i, 0.01 * i, "background", "NO") for i in range(30)])
    ev = evaluate(big, {r.id: r.truth for r in big}, "v", {"tau": 0.1},
                  ReportSettings(n_boot=100))
    assert ev["few"] is None and ev["warnings"] == []
    assert "(too few)" not in tables.compare_table([ev])


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
    # The lidar ROIs are real structures, apart from the strata of the headline set.
    assert {s["name"]: s["n"] for s in ev["strata"]["lighting"]} == {"day": 12}
    assert {c["class"]: c["n"] for c in ev["recall_by_class"]} == {"Car": 3, "Pedestrian": 3}
    assert result["labels"] == {"YES": 6, "NO": 12, "ambiguous": 1}


def test_what_the_verifier_could_not_tell_is_counted_apart_and_said():
    """A verifier's "cannot tell" (GateResult.unverifiable) is scored as not verified,
    and the report says how many of each kind it was; a verifier that told every ROI
    gets no such line."""
    def told(r, cannot):
        s = r.scores["v"]
        return msgspec.structs.replace(r, scores={**r.scores, "v": Score(
            s.score, False if cannot else s.verified, cannot_tell=cannot)})

    records = [told(r, r.id in ("r0", "r1", "r10", "r20")) for r in RECORDS]
    labels = {r.id: r.truth for r in records}
    ev = evaluate(records, labels, "v", {}, ReportSettings(n_boot=200))
    assert ev["cannot_tell"] == {"yes": 2, "no": 1, "real_structure": 1}
    assert ev["operating"]["fn"] == 2          # not verified: counted as a miss here
    by_class = {row["class"]: row["cannot_tell"] for row in ev["recall_by_class"]}
    assert by_class == {"Pedestrian": 1, "Car": 1}
    kinds = {k["kind"]: k for k in ev["negative_kinds"]}
    assert kinds["empty scene"]["cannot_tell_rate"] == pytest.approx(1 / 6)
    text = tables.negative_kinds_table(ev)
    assert "v: could not tell 2 of 8 objects and 1 of 6 negatives (1 real structures" in text
    plain = evaluate(RECORDS, {r.id: r.truth for r in RECORDS}, "v", {},
                     ReportSettings(n_boot=200))
    assert plain["cannot_tell"] == {"yes": 0, "no": 0, "real_structure": 0}
    assert "could not tell" not in tables.negative_kinds_table(plain)
