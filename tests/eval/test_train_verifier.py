"""`aeb train-verifier`: trains hog_linear on the labelled ROIs of `aeb eval`, holds out
a fold of frames and says so in the weights, which `aeb eval report --held-out` reads."""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from services.fusion.roi import Roi
from services.fusion.verifiers import Observation, create
from tests.fusion.test_appearance import COLUMN, ROI, bars
from tools.eval import cli as eval_cli
from tools.eval import labels as labelfile
from tools.eval.frames import load_gray
from tools.eval.records import FrameRef, RoiRecord, read_records, write_records
from tools.eval.train_verifier import fold_of, main, tau_for_recall


def roi_set(tmp: Path, frames: int = 24) -> Path:
    """A ROI folder: per frame, an obstacle-like (vertical bars) or a road-like
    (horizontal stripes) image, its ROI labelled by ground truth."""
    rng = np.random.default_rng(11)
    records = []
    for i in range(frames):
        yes = i % 2 == 0
        path = tmp / f"{i:06d}.png"
        cv2.imwrite(str(path), bars(yes, rng))
        records.append(RoiRecord(
            id=f"synthetic:{i:06d}:0", source="synthetic", session="synthetic",
            frame=f"{i:06d}", t_ns=0, camera="cam", image_w=200, image_h=120,
            roi=(ROI.x, ROI.y, ROI.w, ROI.h), column=(COLUMN.x, COLUMN.y, COLUMN.w, COLUMN.h),
            range_m=10.0,
            kind="object" if yes else "background", frame_ref=FrameRef("image", str(path)),
            truth="YES" if yes else "NO"))
    out = tmp / "rois"
    write_records(out / "rois.jsonl", records)
    return out


def test_trains_on_the_frames_outside_the_held_out_fold(tmp_path, capsys):
    rois = roi_set(tmp_path)
    weights = tmp_path / "w.json"
    assert main([str(rois), "--out", str(weights), "--folds", "2", "--fold", "1",
                 "--cv-folds", "2", "--l2", "10"]) == 0
    data = json.loads(weights.read_text())
    trained = set(data["trained_on"]["frames"])
    held = {f"synthetic:{i:06d}" for i in range(24)} - trained
    assert trained and held
    assert all(fold_of(k, 2) == 0 for k in trained) and all(fold_of(k, 2) == 1 for k in held)
    assert data["trained_on"]["held_out_fold"] == 1 and 0.0 <= data["tau"] <= 1.0
    assert data["trained_on"]["yes"] + data["trained_on"]["no"] == len(trained)
    # The weights work as a verifier, on the frames they never saw.
    v = create("hog_linear", {"weights": str(weights)})
    for r in read_records(rois):
        if r.frame_key in held:
            gray = load_gray(r.frame_ref)
            got = v.verify(Observation(gray, Roi(*r.roi), Roi(*r.column), r.range_m))
            assert got.verified == (r.truth == "YES")
    # The report keeps only the held-out frames.
    kept = eval_cli.held_out(read_records(rois), str(weights))
    assert {r.frame_key for r in kept} == held


def test_labels_override_truth_and_bad_input_is_a_clear_error(tmp_path, capsys):
    rois = roi_set(tmp_path, frames=6)
    labels = tmp_path / "labels.tsv"
    # Every ROI labelled NO: one class only, nothing to train.
    labelfile.write_labels(labels, [labelfile.Label(f"synthetic:{i:06d}:0", "NO", "t", "")
                                    for i in range(6)])
    assert main([str(rois), "--out", str(tmp_path / "w.json"), "--labels", str(labels)]) == 2
    assert "both classes" in capsys.readouterr().err
    assert main([str(rois), "--out", str(tmp_path / "w.json"), "--fold", "3"]) == 2
    assert main([str(tmp_path / "nothing"), "--out", str(tmp_path / "w.json")]) == 2
    assert main([str(rois), "--out", str(tmp_path / "w.json"), "--window", "30x64"]) == 2
    assert not (tmp_path / "w.json").exists()


def test_tau_keeps_the_asked_share_of_the_positives():
    scores = np.linspace(0.0, 1.0, 101)
    y = np.ones(101)
    tau = tau_for_recall(scores, y, 0.9)
    assert np.mean(scores >= tau) >= 0.9 and np.mean(scores > tau) < 0.9
    assert tau_for_recall(scores, y, 1.0) == pytest.approx(0.0)
