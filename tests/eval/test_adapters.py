"""Data-set adapters on generated KITTI and View-of-Delft folders: the paper's ROIs at its
pixel scale, both kinds of negatives, depth for the verifiers that use it."""

from collections.abc import Mapping
from dataclasses import replace

import numpy as np
import pytest

from aeb_radar_camera.services.fusion import verifiers
from aeb_radar_camera.services.fusion.verifiers import GateResult, Observation, ParamValue
from aeb_radar_camera.tools.eval.adapters import detect, frame_ids, kitti
from aeb_radar_camera.tools.eval.adapters.paper_rois import (
    Candidate,
    PaperRoiSettings,
    ground_plane,
    object_candidates,
    scaled,
    standing_in_column,
)
from aeb_radar_camera.tools.eval.dataset_rois import DatasetSettings, dataset_records
from aeb_radar_camera.tools.eval.frames import load_gray
from aeb_radar_camera.tools.eval.scoring import Scorer, VerifierSpec, default_specs
from aeb_radar_camera.tools.sim.world import nearest_point
from tests.eval.fixtures import (
    KITTI_BOXES,
    KITTI_P2,
    KITTI_R0,
    KITTI_SIZE,
    KITTI_TR,
    VOD_CLUTTER_XY,
    velo_from_rect,
    write_kitti,
    write_vod,
)

FOCAL = 449.0


@pytest.fixture(scope="module")
def kitti_split(tmp_path_factory):
    return write_kitti(tmp_path_factory.mktemp("kitti"), n_frames=2)


@pytest.fixture(scope="module")
def vod_root(tmp_path_factory):
    return write_vod(tmp_path_factory.mktemp("vod") / "vod")


def kitti_records(split, settings=None, specs=None):
    counters: dict[str, int] = {}
    errors: list[str] = []
    recs = dataset_records("kitti", split, frame_ids("kitti", split),
                           settings or DatasetSettings(), Scorer(specs or default_specs()),
                           counters, errors)
    return recs, counters, errors


def paper_roi_by_p2(box, sx, sy):
    """The ROI written out with KITTI's own P2: the 1.08 m x 2.2 m column at the box's
    nearest point (from the camera), projected, boxed, padded by 22 px at the scale."""
    velo = velo_from_rect(box.corners_rect()[:4])
    cam_centre = velo_from_rect(-np.linalg.solve(KITTI_P2[:, :3], KITTI_P2[:, 3])[None])[0]
    nx, ny = nearest_point(velo[:, :2], cam_centre[0], cam_centre[1])
    z0 = velo[:, 2].mean()
    pts = np.array([[nx, ny + dy, z0 + dz] for dy in (-0.54, 0.54) for dz in (0.0, 2.2)])
    rect = (pts @ KITTI_TR[:, :3].T + KITTI_TR[:, 3]) @ KITTI_R0.T
    uvw = np.c_[rect, np.ones(4)] @ KITTI_P2.T
    u = (uvw[:, 0] / uvw[:, 2] + 0.5) * sx - 0.5
    v = (uvw[:, 1] / uvw[:, 2] + 0.5) * sy - 0.5
    x0, y0 = np.floor(u.min() + 0.5) - 22, np.floor(v.min() + 0.5) - 22
    x1, y1 = np.floor(u.max() + 0.5) + 1 + 22, np.floor(v.max() + 0.5) + 1 + 22
    return x0, y0, x1 - x0, y1 - y0


def test_kitti_positives_are_the_papers_column_at_the_papers_pixel_scale(kitti_split):
    assert detect(kitti_split) == "kitti"
    recs, counters, errors = kitti_records(kitti_split)
    assert errors == [] and counters["frames"] == 2
    objects = [r for r in recs if r.kind == "object"]
    # The car and the pedestrian; not the car at 40 m, not the van (another class).
    assert sorted(r.obj_class for r in objects if r.frame == "000000") == ["Car", "Pedestrian"]
    w, h = round(KITTI_SIZE[0] * FOCAL / KITTI_P2[0, 0]), round(KITTI_SIZE[1] * FOCAL /
                                                                KITTI_P2[0, 0])
    sx, sy = w / KITTI_SIZE[0], h / KITTI_SIZE[1]
    for r in objects:
        assert (r.image_w, r.image_h) == (w, h) and r.truth == "YES"
        box = KITTI_BOXES[0] if r.obj_class == "Car" else KITTI_BOXES[1]
        x, y, rw, rh = paper_roi_by_p2(box, sx, sy)
        got = r.roi
        # Clipped to the image like fusion's ROIs.
        assert got[0] == max(0, x) and got[1] == max(0, y)
        assert got[0] + got[2] == min(w, x + rw) and got[1] + got[3] == min(h, y + rh)
    # The verifiers saw the image at that scale, JPEG-coded as the camera would.
    gray = load_gray(objects[0].frame_ref)
    assert gray.shape == (h, w) and objects[0].frame_ref.jpeg_quality == 80


def test_kitti_negatives_background_rows_and_lidar_structure(kitti_split):
    recs, _, _ = kitti_records(kitti_split)
    frame = kitti.read_frame(kitti_split, "000000")
    sc = scaled(frame, FOCAL)
    occupied = [sc.box(b.bbox) for b in frame.boxes] + [sc.box(b) for b in frame.dontcare]
    positives = {r.id: r for r in recs if r.kind == "object"}
    background = [r for r in recs if r.kind == "background"]
    assert background and all(r.truth == "NO" for r in background)
    for r in background:
        x, y, w, h = r.roi
        assert any((p.roi[1], p.roi[2], p.roi[3]) == (y, w, h) for p in positives.values())
        # Its column is the positive's column moved with the ROI, not the padded ROI:
        # a verifier of the column sees a background column of the object's size.
        pos = next(p for p in positives.values() if (p.roi[1], p.roi[2], p.roi[3]) == (y, w, h))
        assert r.column[1:] == pos.column[1:] and r.column != r.roi
        assert r.column[0] - x == pos.column[0] - pos.roi[0]
        for bx0, by0, bx1, by1 in occupied:
            assert x + w - 1 < bx0 or x > bx1 or y + h - 1 < by0 or y > by1
    # The wall is the only lidar structure: ground, the boxes' own points are not.
    lidar = [r for r in recs if r.kind == "lidar" and r.frame == "000000"]
    assert len(lidar) == 1 and not lidar[0].object_in_view
    wall_u = (KITTI_P2[0, 0] * 6.0 / 9.0 + KITTI_P2[0, 2] + 0.5) * sc.sx - 0.5
    assert lidar[0].roi[0] < wall_u < lidar[0].roi[0] + lidar[0].roi[2]
    assert lidar[0].range_m == pytest.approx(np.hypot(6.0, 9.0), abs=0.3)


def test_a_background_column_on_the_wall_is_a_background_with_something_standing(
        kitti_split):
    """A background ROI is an empty scene only where no lidar stands in its column at or
    before its range: moved onto the unlabelled wall, it is a real structure."""
    frame = kitti.read_frame(kitti_split, "000000")
    sc = scaled(frame, FOCAL)
    assert frame.lidar is not None
    plane = ground_plane(frame.lidar, np.random.default_rng(0))
    assert plane is not None
    s = PaperRoiSettings()
    car = next(c for c in object_candidates(frame, sc, s) if c.obj_class == "Car")

    def moved(range_m: float, x_over_z: float) -> Candidate:
        """The car's ROI moved to look along x / z = `x_over_z` (camera frame)."""
        u = (KITTI_P2[0, 0] * x_over_z + KITTI_P2[0, 2] + 0.5) * sc.sx - 0.5
        col = car.column
        shift = round(u - (col.x + col.w / 2))
        return replace(car, kind="background", roi=car.roi._replace(x=car.roi.x + shift),
                       column=col._replace(x=col.x + shift), range_m=range_m)
    # The wall (6 m right, 9-14 m ahead: 10.8-15.2 m away) at a 12 m range: standing;
    # at 8 m it lies beyond the range; between the pedestrian and the car only road.
    on_wall, short, road = moved(12.0, 0.6), moved(8.0, 0.6), moved(12.0, -0.2)
    assert standing_in_column(frame, sc, [on_wall, short, road], frame.lidar, plane,
                              s) == [True, False, False]
    recs, _, _ = kitti_records(kitti_split)
    kinds = {r.kind for r in recs}
    assert "background" in kinds and kinds <= {"object", "background",
                                              "background_standing", "lidar"}


def depth_probe(params: Mapping[str, ParamValue]) -> verifiers.Verifier:
    class Probe:
        name = "depth_probe"
        needs_depth = True

        def params(self) -> dict[str, ParamValue]:
            return {}

        def verify(self, obs: Observation) -> GateResult:
            assert obs.depth_m is not None
            x, y, w, h = obs.roi
            d = obs.depth_m[y:y + h, x:x + w]
            near = np.abs(d - obs.range_m) < 1.5
            share = float(near.mean())
            return GateResult(share, share > 0.0)

    return Probe()


def test_depth_reaches_verifiers_that_need_it_and_is_not_applicable_without(kitti_split,
                                                                           monkeypatch):
    monkeypatch.setitem(verifiers._REGISTRY, "depth_probe", depth_probe)
    specs = [VerifierSpec("depth_probe", "depth_probe"),
             VerifierSpec("edge_density", "edge_density")]
    recs, _, _ = kitti_records(kitti_split, specs=specs)
    car = next(r for r in recs if r.obj_class == "Car")
    background = [r for r in recs if r.kind == "background"]
    assert car.has_depth and car.scores["depth_probe"].score > 0
    # The car's own points stand at its range; background ROIs only hold road there.
    assert car.scores["depth_probe"].score > max(r.scores["depth_probe"].score
                                                 for r in background)
    recs, _, _ = kitti_records(kitti_split, DatasetSettings(depth="none"), specs)
    assert all(r.scores["depth_probe"] == r.scores["depth_probe"].__class__(None, None)
               for r in recs)
    assert all(r.scores["edge_density"].score is not None for r in recs)
    noisy, _, _ = kitti_records(kitti_split, DatasetSettings(depth="d435"), specs)
    assert len(noisy) == len(recs)


def test_a_bad_label_file_is_counted_and_the_other_frames_go_on(tmp_path):
    split = write_kitti(tmp_path, n_frames=2)
    (split / "label_2" / "000001.txt").write_text("Car 0.0 0 0.0 1 2 3\n")
    recs, counters, errors = kitti_records(split)
    assert counters["frame_unreadable"] == 1 and counters["frames"] == 1
    assert "000001" in errors[0] and "expected 15 fields" in errors[0]
    assert {r.frame for r in recs} == {"000000"}


def test_vod_radar_returns_on_nothing_are_the_papers_negatives(vod_root):
    assert detect(vod_root) == "vod"
    counters: dict[str, int] = {}
    errors: list[str] = []
    recs = dataset_records("vod", vod_root, frame_ids("vod", vod_root), DatasetSettings(),
                           Scorer(default_specs()), counters, errors)
    assert errors == []
    assert sorted(r.obj_class for r in recs if r.kind == "object") == ["Car", "Cyclist"]
    radar = [r for r in recs if r.kind == "radar"]
    # The clutter return only: the return on the car is not a negative.
    assert len(radar) == 1 and radar[0].truth == "NO"
    assert radar[0].range_m == pytest.approx(np.hypot(*VOD_CLUTTER_XY), abs=0.3)
    assert not [r for r in recs if r.kind == "lidar"]
    # 1936 px wide at f 1495.5 resampled to f 449.
    assert recs[0].image_w == round(1936 * FOCAL / 1495.5)


def test_the_depth_verifier_passes_the_objects_and_rejects_their_background(kitti_split):
    specs = [VerifierSpec("depth", "depth")]
    recs, _, _ = kitti_records(kitti_split, DatasetSettings(depth="d435"), specs)
    objects = [r for r in recs if r.kind == "object"]
    walls = [r for r in recs if r.kind == "lidar"]
    # Background ROIs avoid labelled boxes, not the (unlabelled) wall: depth sees the wall.
    background = [r for r in recs if r.kind == "background"
                  and not any(w.frame == r.frame and abs(w.roi[0] - r.roi[0]) < r.roi[2]
                              for w in walls)]
    assert objects and background and walls
    # The fixture's cloud is sparse and does not occlude: ground points behind the car
    # fall between its own, so the car scores far below 1 - but above its background.
    assert all(r.scores["depth"].score > 0.05 for r in objects)
    assert any(r.scores["depth"].verified for r in objects)
    assert all(r.scores["depth"].score == 0.0 for r in background)
    assert all(r.scores["depth"].verified for r in walls)
    # A background ROI keeps its positive's column (not the padded box), moved with it.
    sizes = {tuple(r.column[1:]) for r in objects}
    for r in background:
        x, y, w, h = r.column
        assert (y, w, h) in sizes and tuple(r.column) != tuple(r.roi)
        assert r.roi[0] <= x and x + w <= r.roi[0] + r.roi[2]
