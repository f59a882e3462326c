"""`aeb train-verifier`: trains hog_linear on the labelled ROIs of `aeb eval`, holds out
a fold of frames (known by content, never by path) and says so in the weights, which
`aeb eval report --held-out` reads; with --seeds only generated cases of the train split,
never the demo's scenarios."""

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from aeb_radar_camera.services.fusion.roi import Roi
from aeb_radar_camera.services.fusion.verifiers import Observation, create
from aeb_radar_camera.tools.eval import evaluate as eval_run
from aeb_radar_camera.tools.eval import labels as labelfile
from aeb_radar_camera.tools.eval.cli import main as eval_cli_main
from aeb_radar_camera.tools.eval.frames import frame_digest, load_gray
from aeb_radar_camera.tools.eval.records import FrameRef, RoiRecord, read_records, write_records
from aeb_radar_camera.tools.eval.train_verifier import main
from aeb_radar_camera.tools.eval.training import fold_of, tau_for_recall
from tests.fusion.test_appearance import COLUMN, ROI, bars


def roi_set(tmp: Path, frames: int = 24, scenario=lambda i: "", session: str = "synthetic",
            images: Path | None = None) -> Path:
    """A ROI folder: per frame, an obstacle-like (vertical bars) or a road-like
    (horizontal stripes) image, its ROI labelled by ground truth. The records carry no
    content digest (as sets written before there was one): it is computed from the
    frame. With `images`, the frames are those PNGs (the same pictures elsewhere)."""
    rng = np.random.default_rng(11)
    records = []
    folder = tmp / session
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(frames):
        yes = i % 2 == 0
        path = folder / f"{i:06d}.png"
        if images is None:
            cv2.imwrite(str(path), bars(yes, rng))
        else:
            shutil.copy(images / f"{i:06d}.png", path)
        records.append(RoiRecord(
            id=f"{session}:{i:06d}:0", source="synthetic", session=session,
            frame=f"{i:06d}", t_ns=0, camera="cam", image_w=200, image_h=120,
            roi=(ROI.x, ROI.y, ROI.w, ROI.h), column=(COLUMN.x, COLUMN.y, COLUMN.w, COLUMN.h),
            range_m=10.0,
            kind="object" if yes else "background", frame_ref=FrameRef("image", str(path)),
            truth="YES" if yes else "NO", scenario=scenario(i)))
    out = tmp / f"rois-{session}"
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
    # Folds by content: each frame's fold is that of its picture's digest.
    digest = {r.frame_key: frame_digest(r.frame_ref) for r in read_records(rois)}
    assert all(fold_of(digest[k], 2) == 0 for k in trained)
    assert all(fold_of(digest[k], 2) == 1 for k in held)
    assert set(data["trained_on"]["frame_sha256"]) == {digest[k] for k in trained}
    assert data["trained_on"]["held_out_fold"] == 1 and 0.0 <= data["tau"] <= 1.0
    assert data["trained_on"]["yes"] + data["trained_on"]["no"] == len(trained)
    # The cross-validation inside the training frames had folds to validate on.
    assert data["trained_on"]["cv_auc"] is not None
    # The weights work as a verifier, on the frames they never saw.
    v = create("hog_linear", {"weights": str(weights)})
    for r in read_records(rois):
        if r.frame_key in held:
            gray = load_gray(r.frame_ref)
            got = v.verify(Observation(gray, Roi(*r.roi), Roi(*r.column), r.range_m))
            assert got.verified == (r.truth == "YES")
    # The report keeps only the held-out frames.
    kept = eval_run.held_out(read_records(rois), str(weights))
    assert {r.frame_key for r in kept} == held


def test_the_same_frames_under_another_path_are_training_frames(tmp_path, capsys):
    rois = roi_set(tmp_path)
    weights = tmp_path / "w.json"
    assert main([str(rois), "--out", str(weights), "--folds", "2", "--fold", "1",
                 "--cv-folds", "2", "--l2", "10"]) == 0
    trained = set(json.loads(weights.read_text())["trained_on"]["frames"])
    # The same pictures copied to another folder, another session name, another path.
    copy = roi_set(tmp_path, session="elsewhere", images=tmp_path / "synthetic")
    records = read_records(copy)
    assert {r.frame_ref.path for r in records}.isdisjoint(
        {r.frame_ref.path for r in read_records(rois)})
    kept = eval_run.held_out(records, str(weights))
    # Only the copies of the held-out pictures are held out (by path: all 24 were).
    assert {r.frame for r in kept} == {f"{i:06d}" for i in range(24)} - {
        k.split(":")[1] for k in trained}
    assert len(kept) == 24 - len(trained)
    assert f"{len(trained)} ROIs are of frames it was trained on" in capsys.readouterr().err
    # The copies fall in the same folds: training on them holds out the same pictures.
    again = tmp_path / "w2.json"
    assert main([str(copy), "--out", str(again), "--folds", "2", "--fold", "1",
                 "--cv-folds", "2", "--l2", "10"]) == 0
    assert (json.loads(again.read_text())["trained_on"]["frame_sha256"]
            == json.loads(weights.read_text())["trained_on"]["frame_sha256"])


def test_held_out_refuses_weights_that_know_frames_only_by_path(tmp_path, capsys):
    rois = roi_set(tmp_path, frames=6)
    weights = tmp_path / "w.json"
    assert main([str(rois), "--out", str(weights), "--cv-folds", "2", "--l2", "10"]) == 0
    data = json.loads(weights.read_text())
    del data["trained_on"]["frame_sha256"]
    weights.write_text(json.dumps(data))
    with pytest.raises(ValueError, match="frame_sha256"):
        eval_run.held_out(read_records(rois), str(weights))
    assert eval_cli_main(["compare", str(rois), "--held-out", str(weights), "--no-plots",
                          "--boot", "50"]) == 2
    assert "train them again" in capsys.readouterr().err


def test_seeds_train_on_the_train_split_only_never_the_demo(tmp_path, capsys):
    # Frames of generated cases with seeds 1000-1023 (train) and one demo scenario.
    names = {i: f"CPNA-25_20kph_s{1000 + i}" for i in range(24)}
    names[0] = "bicycle_crossing_20kph"
    names[1] = "CPNA-25_20kph_s2001"           # a held-out seed
    rois = roi_set(tmp_path, scenario=lambda i: names[i])
    weights = tmp_path / "w.json"
    assert main([str(rois), "--out", str(weights), "--seeds", "1002-1013",
                 "--cv-folds", "2", "--l2", "10"]) == 0
    err = capsys.readouterr().err
    assert "1 ROIs of the demo's own scenarios left out" in err
    t = json.loads(weights.read_text())["trained_on"]
    assert t["split"] == "train" and t["seeds_asked"] == "1002-1013"
    assert t["seeds"] == [[1002, 1013]]
    assert t["scenarios"] == sorted(names[i] for i in range(2, 14))
    assert t["demo_scenario_rois_left_out"] == 1
    # A seed outside the train split is refused: figures are made on those.
    assert main([str(rois), "--out", str(tmp_path / "x.json"), "--seeds", "1990-2010"]) == 2
    assert "seed 2000 is not in the train split" in capsys.readouterr().err
    assert main([str(rois), "--out", str(tmp_path / "x.json"), "--seeds", "heldout:5"]) == 2
    assert not (tmp_path / "x.json").exists()
    # Without --seeds every ROI but the demo scenario's is trained on.
    assert main([str(rois), "--out", str(weights), "--cv-folds", "2", "--l2", "10"]) == 0
    t = json.loads(weights.read_text())["trained_on"]
    assert "bicycle_crossing_20kph" not in t["scenarios"] and len(t["frames"]) == 23


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


def test_a_frame_that_cannot_be_read_is_not_called_held_out(tmp_path, capsys):
    rois = roi_set(tmp_path, frames=12)
    weights = tmp_path / "w.json"
    assert main([str(rois), "--out", str(weights), "--folds", "2", "--fold", "1",
                 "--cv-folds", "2", "--l2", "10"]) == 0
    capsys.readouterr()
    records = read_records(rois)
    (tmp_path / "synthetic" / "000001.png").unlink()
    kept = eval_run.held_out(records, str(weights))
    # Without its picture a frame cannot be shown to be unseen: left out, said so.
    assert "synthetic:000001" not in {r.frame_key for r in kept}
    err = capsys.readouterr().err
    assert "synthetic:000001 left out of the held-out set" in err and "1 frames unreadable" in err
