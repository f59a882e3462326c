"""The label file, labels from ground truth, stratified sampling and the label session."""

import pytest

from aeb_radar_camera.tools.eval.labels import (
    Label,
    LabelFileError,
    LabelWriter,
    read_labels,
    resolve,
    truth_labels,
)
from aeb_radar_camera.tools.eval.labelweb import LabelSession, pick_sample
from aeb_radar_camera.tools.eval.records import FrameRef, RoiRecord
from aeb_radar_camera.tools.eval.sampling import density_band, stratified, stratum_key


def rec(i, density=0.03, lighting="day", truth=None, session="s1"):
    return RoiRecord(id=f"r{i}", source="recording", session=session, frame=str(i), t_ns=0,
                     camera="front", image_w=10, image_h=10, roi=(0, 0, 2, 2),
                     column=(0, 0, 2, 2), range_m=8.0, kind="track",
                     frame_ref=FrameRef("none", ""), truth=truth, density=density,
                     lighting=lighting)


def test_label_file_appends_later_lines_win_and_bad_lines_are_named(tmp_path):
    path = tmp_path / "labels.tsv"
    w = LabelWriter(path)
    w.add(Label("a", "YES", "ana", "2026-01-01T00:00:00Z"))
    w.add(Label("b", "ambiguous", "ana", "2026-01-01T00:00:01Z"))
    w.add(Label("a", "NO", "bo", "2026-01-01T00:00:02Z"))
    w.close()
    text = path.read_text()
    assert text.startswith("# aeb labels v1") and text.count("\n") == 4
    got = read_labels(path)
    assert got["a"].value == "NO" and got["a"].who == "bo" and got["b"].value == "ambiguous"
    path.write_text(text + "c\tMAYBE\tana\tnow\n")
    with pytest.raises(LabelFileError, match=r"labels.tsv:5: label 'MAYBE'"):
        read_labels(path)
    assert read_labels(tmp_path / "missing.tsv") == {}


def test_ground_truth_labels_and_the_label_file_overrides_them():
    records = [rec(0, truth="YES"), rec(1, truth="NO"), rec(2)]
    labels = truth_labels(records, "kitti-annotations", "t")
    assert [(x.roi_id, x.value, x.who) for x in labels] == [("r0", "YES", "kitti-annotations"),
                                                           ("r1", "NO", "kitti-annotations")]
    given = {"r1": Label("r1", "YES", "ana", "t"), "r2": Label("r2", "ambiguous", "ana", "t")}
    assert resolve(records, given) == {"r0": "YES", "r1": "YES", "r2": "ambiguous"}


def test_stratified_sample_takes_equal_shares_of_density_bands_and_conditions():
    # 90 ROIs in one band by day, 10 in each other band, 10 at night.
    records = ([rec(i, 0.2) for i in range(90)] + [rec(100 + i, 0.01) for i in range(10)]
               + [rec(200 + i, 0.03) for i in range(10)] + [rec(300 + i, 0.07)
                                                           for i in range(10)]
               + [rec(400 + i, 0.2, "night") for i in range(10)])
    key = stratum_key(["lighting"], [], (0.025, 0.05, 0.1))
    sample = stratified(records, 40, key, seed=3)
    assert len(sample) == 40 and len({r.id for r in sample}) == 40
    bands = [(density_band(r.density), r.lighting) for r in sample]
    for stratum in {(density_band(r.density), r.lighting) for r in records}:
        assert bands.count(stratum) == 8
    # Too few in a stratum: the others make up the difference.
    assert len(stratified(records, 100, key)) == 100
    assert stratified(records, 40, key, seed=3) == sample
    with pytest.raises(ValueError, match="unknown strata"):
        stratum_key(["weather"], [], (0.05,))


def test_session_resumes_skips_and_goes_back(tmp_path):
    records = [rec(i, 0.01 * i) for i in range(6)]
    path = tmp_path / "labels.tsv"
    items = pick_sample(records, path, 4, ["lighting"], [], (0.025,), 0)
    assert (tmp_path / "labels.tsv.sample").read_text().count("\n") == 4
    s = LabelSession(items, path, "ana")
    first = s.state()["current"]["id"]
    st = s.label(first, "YES")
    second = st["current"]["id"]
    st = s.skip(second)
    third = st["current"]["id"]
    assert third not in (first, second) and st["skipped"] == 1
    st = s.label(third, "NO")
    with pytest.raises(ValueError, match="not the ROI on screen"):
        s.label(first, "NO")
    st = s.back(st["current"]["id"])
    assert st["current"]["id"] == third and st["current"]["label"] == "NO"
    s.close()
    # A new session on the same files: the same sample, the labelled ones not shown.
    again = pick_sample(records, path, 4, ["lighting"], [], (0.025,), 99)
    assert [r.id for r in again] == [r.id for r in items]
    s2 = LabelSession(again, path, "ana")
    st = s2.state()
    assert st["labelled"] == 2 and st["yes"] == 1 and st["no"] == 1
    assert st["current"]["id"] not in (first, third)
    s2.close()
