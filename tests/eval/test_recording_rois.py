"""ROIs from a recording in the project's MCAP layout are the ones fusion builds: the
frame fusion would hold and choose, the track predicted to its capture time, fusion's
projector with its padding; a simulator run's tracks are labelled by its ground truth."""

import math

import msgspec
import numpy as np
import pytest

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import parse_config
from aeb_radar_camera.common.imaging import decode_gray
from aeb_radar_camera.common.keys import CAMERA_INFO
from aeb_radar_camera.common.messages import CompressedFrame, decode
from aeb_radar_camera.services.fusion.roi import ColumnGeometry, ColumnProjector, Roi
from aeb_radar_camera.services.fusion.verifiers import Observation, create
from aeb_radar_camera.tools.eval import sim_truth
from aeb_radar_camera.tools.eval.frames import frame_digest
from aeb_radar_camera.tools.eval.recording import RecordingSettings, recording_records
from aeb_radar_camera.tools.eval.scoring import Scorer, VerifierSpec, default_specs
from aeb_radar_camera.tools.recording.reader import Recording, RecordingError
from aeb_radar_camera.tools.recording.writer import RecordingWriter
from tests.eval.fixtures import (
    BOX_SPEED,
    GHOST_XY,
    T0,
    box_face_x,
    camera_info,
    write_sim_recording,
)
from tests.fusion.helpers import CAL

MAX_SKEW_NS = 100_000_000


@pytest.fixture(scope="module")
def rec(tmp_path_factory):
    # Frame 2 is truncated: the nearest frame to the second radar cycle, so the choice
    # must fall back to frame 1 as fusion (which never holds an undecodable frame) would.
    return write_sim_recording(tmp_path_factory.mktemp("rec") / "drive.mcap",
                               corrupt_seqs=(2,))


def expected_roi(rec, radar_stamp, radar_log, x, y, vx):
    """Fusion's rules written out: the last 4 decodable frames received before the
    cycle, the one nearest in capture time (within 100 ms), the track predicted to it."""
    ring = [f for f in rec.frames if f[2] <= radar_log][-4:]
    seq, stamp, _ = min(ring, key=lambda f: abs(f[1] - radar_stamp))
    assert abs(stamp - radar_stamp) <= MAX_SKEW_NS
    dt = (stamp - radar_stamp) / 1e9
    box = ColumnProjector(CAL, ColumnGeometry(2.2, 0.0, 22)).boxes(
        np.array([[x + vx * dt, y]]))[0]
    assert box is not None
    return seq, box


def test_every_confirmed_track_in_range_gets_fusions_roi_and_frame(rec):
    counters: dict[str, int] = {}
    records = recording_records(rec.path, RecordingSettings(), Scorer(default_specs()),
                                counters)
    tracks = [r for r in records if r.kind == "track"]
    # Track 1 (the box) and 2 (the ghost) every cycle; 3 is beyond 25 m, 4 unconfirmed.
    assert sorted({r.track_id for r in tracks}) == [1, 2]
    assert len(tracks) == 2 * len(rec.cycles)
    assert counters["radar_cycles"] == len(rec.cycles)
    assert counters["frame_jpeg"] == 1
    for r in tracks:
        stamp, log = next(c for c in rec.cycles if c[0] == r.t_ns)
        if r.track_id == 1:
            x, y, vx = box_face_x(stamp), 0.0, -BOX_SPEED
        else:
            (x, y), vx = GHOST_XY, 0.0
        seq, (roi, column) = expected_roi(rec, stamp, log, x, y, vx)
        assert r.frame == f"front:{seq}"
        assert tuple(r.roi) == tuple(roi) and tuple(r.column) == tuple(column)
        assert r.range_m == pytest.approx(math.hypot(x, y))
        assert r.frame_ref.kind == "mcap" and r.frame_ref.seq == seq
    assert [r.frame for r in tracks if r.t_ns == rec.cycles[1][0]] == ["front:1"] * 2


def test_scores_are_the_verifiers_on_the_decoded_frame(rec):
    records = recording_records(rec.path, RecordingSettings(), Scorer(default_specs()), {})
    gate = create("edge_density")
    frames = {}
    for m in Recording.open(rec.path).records(["aeb/ego/camera/front/jpeg"]):
        f = decode(m.data, CompressedFrame)
        frames[f.header.seq] = f.jpeg
    for r in records[:12]:
        gray = decode_gray(frames[r.frame_ref.seq])
        expected = gate.verify(Observation(gray, Roi(*r.roi), Roi(*r.column), r.range_m))
        assert r.scores["edge_density"].score == expected.score == r.density
        assert set(r.scores) == {s.name for s in default_specs()}
        assert r.scores["hog_people"].score is not None
        assert r.scores["edge_density"].us > 0
    # Full-frame timing once per frame used.
    timed = [r for r in records if r.frame_canny_us is not None]
    assert len(timed) == len({r.frame for r in records})


def test_records_know_their_frame_by_content_and_their_scenario(rec, tmp_path):
    records = recording_records(rec.path, RecordingSettings(), Scorer(default_specs()), {})
    by_frame: dict[str, set[str]] = {}
    for r in records:
        by_frame.setdefault(r.frame, set()).add(r.frame_sha256)
    # One digest per frame (background ROIs share their frame's), a distinct one each.
    assert all(len(d) == 1 for d in by_frame.values())
    assert len({next(iter(d)) for d in by_frame.values()}) == len(by_frame)
    assert {r.scenario for r in records} == {"test"}
    # The stored digest is the one computed from the frame again: sets written without
    # it are judged the same way; a copy of the recording elsewhere gives the same.
    copy = tmp_path / "elsewhere.mcap"
    copy.write_bytes(rec.path.read_bytes())
    for r in records[:6]:
        assert frame_digest(r.frame_ref) == r.frame_sha256
        moved = msgspec.structs.replace(r.frame_ref, path=str(copy))
        assert frame_digest(moved) == r.frame_sha256


def test_simulator_truth_labels_tracks_and_places_background_off_the_objects(rec):
    records = recording_records(rec.path, RecordingSettings(), Scorer(default_specs()), {})
    box = [r for r in records if r.track_id == 1]
    ghost = [r for r in records if r.track_id == 2]
    assert {(r.truth, r.obj_class) for r in box} == {("YES", "box")}
    assert {(r.truth, r.obj_class) for r in ghost} == {("NO", "")}
    background = [r for r in records if r.kind == "background"]
    assert len(background) == 2 * len(box)
    truth = sim_truth.Truth()
    for m in Recording.open(rec.path).records(["aeb/ego/sim/world"]):
        truth.add(m.data, {})
    for r in background:
        pos = next(p for p in box if p.id == r.id.rsplit(":", 1)[0])
        assert (r.roi[1], r.roi[2], r.roi[3]) == (pos.roi[1], pos.roi[2], pos.roi[3])
        # The positive's column moved with the ROI, not the padded ROI itself.
        assert r.column[1:] == pos.column[1:] and r.column != r.roi
        assert r.column[0] - r.roi[0] == pos.column[0] - pos.roi[0]
        world = truth.world_at(r.t_ns)
        assert world is not None
        for x0, y0, x1, y1 in sim_truth.object_boxes(world, r.t_ns, CAL):
            x, y, w, h = r.roi
            assert x + w - 1 < x0 or x > x1 or y + h - 1 < y0 or y > y1
        assert r.truth == "NO"


def test_fusion_config_geometry_and_calibration_are_used(rec, tmp_path):
    cfg = parse_config({"fusion": {"roi": {"padding_px": 10, "column_half_width_m": 0.3},
                                   "frames": {"align": False}}}, FusionConfig)
    settings = RecordingSettings(fusion=cfg.fusion, background_per_object=0)
    records = recording_records(rec.path, settings, Scorer([VerifierSpec("edge_density",
                                                                         "edge_density")]), {})
    r = next(r for r in records if r.track_id == 2)
    column = ColumnProjector(CAL, ColumnGeometry(2.2, 0.3, 10)).boxes(np.array([GHOST_XY]))[0]
    assert column is not None and tuple(r.roi) == tuple(column[0])
    # align = false: the newest frame received, whatever its capture time.
    _stamp, log = next(c for c in rec.cycles if c[0] == r.t_ns)
    newest = [f for f in rec.frames if f[2] <= log][-1]
    assert r.frame == f"front:{newest[0]}"
    # A calibration of another size: every frame is rejected and counted, none used.
    small = tmp_path / "small.toml"
    small.write_text('[camera]\nwidth = 640\nheight = 480\nfx = 615.0\nfy = 615.0\n'
                     'cx = 320.0\ncy = 240.0\n[extrinsics.pose]\nposition_m = [-0.8, 0.0, 1.3]\n')
    counters: dict[str, int] = {}
    got = recording_records(rec.path, RecordingSettings(calibrations={"front": str(small)}),
                            Scorer(default_specs()), counters)
    assert got == [] and counters["frame_size"] > 0 and counters["cycle_without_frame"] > 0
    assert Calibration.load(small).width == 640


def test_a_file_without_radar_or_not_mcap_is_a_clear_error(tmp_path):
    empty = tmp_path / "empty.mcap"
    with RecordingWriter(empty) as w:
        w.write_message(CAMERA_INFO.key("ego", camera="front"), camera_info(CAL, T0), T0)
    with pytest.raises(RecordingError, match="no RadarTracks channel"):
        recording_records(empty, RecordingSettings(), Scorer(default_specs()), {})
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    with pytest.raises(RecordingError, match="not an MCAP"):
        recording_records(junk, RecordingSettings(), Scorer(default_specs()), {})


def test_recorded_depth_reaches_the_depth_verifier_paired_by_capture_stamp(tmp_path, rec):
    with_depth = write_sim_recording(tmp_path / "depth.mcap", with_depth=True,
                                     depth_every=2)
    counters: dict[str, int] = {}
    specs = [VerifierSpec("depth", "depth"), VerifierSpec("edge_density", "edge_density")]
    records = recording_records(with_depth.path, RecordingSettings(), Scorer(specs),
                                counters)
    scored = [r for r in records if r.scores["depth"].score is not None]
    # Depth is recorded with every other frame: the others leave depth not applicable.
    assert scored and len(scored) < len(records) and counters["frame_without_depth"] > 0
    assert all(r.has_depth for r in scored)
    box = [r for r in scored if r.track_id == 1]
    ghost = [r for r in scored if r.track_id == 2]
    background = [r for r in scored if r.kind == "background"]
    assert box and ghost and background
    assert all(r.scores["depth"].verified for r in box)
    assert not any(r.scores["depth"].verified for r in ghost + background)
    # Without a depth topic every depth score is not applicable, nothing counted.
    counters = {}
    plain = recording_records(rec.path, RecordingSettings(), Scorer(specs), counters)
    assert all(r.scores["depth"].score is None for r in plain)
    assert "frame_without_depth" not in counters
