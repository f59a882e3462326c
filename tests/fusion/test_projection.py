"""The column projection against hand-computed pixels, with distortion; the ROI sizes
of the example calibration at 8 and 25 m; a track predicted to the frame's time."""

import numpy as np
import pytest

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.messages import Verification
from aeb_radar_camera.services.fusion.roi import ColumnGeometry, ColumnProjector, Roi
from tests.fusion.helpers import CAL, MS, T0, feed, frame, make_core, run, track

FRAME_PIXELS = 848 * 480


def projector(cal: Calibration = CAL, **geometry) -> ColumnProjector:
    return ColumnProjector(cal, ColumnGeometry(**geometry))


def roi_at(x_m: float, y_m: float, **geometry) -> Roi:
    roi = projector(**geometry).rois(np.array([[x_m, y_m]]))[0]
    assert roi is not None
    return roi


def test_column_end_points_match_the_pinhole_model_by_hand():
    # Camera 1.3 m up, 0.8 m behind the radar, level: a track at (8, 0) is 8.8 m deep.
    uv, valid = projector().project_columns(np.array([[8.0, 0.0], [8.0, 1.0]]))
    assert valid.all()
    foot, head = uv[0, 0], uv[0, -1]
    assert foot == pytest.approx([424.0, 240.0 + 615.0 * 1.3 / 8.8])     # v = 330.85
    assert head == pytest.approx([424.0, 240.0 - 615.0 * 0.9 / 8.8])     # v = 177.10
    # 1 m to the left moves the column 615 / 8.8 = 69.9 px left.
    assert uv[1, 0, 0] == pytest.approx(424.0 - 615.0 / 8.8)


def test_roi_is_the_column_box_plus_22_px_clipped_to_the_image():
    roi = roi_at(8.0, 0.0)
    # Columns 424 +- 22; rows round(177.10) - 22 .. round(330.85) + 22.
    assert roi == Roi(402, 155, 45, 199)


@pytest.mark.parametrize(("x_m", "roi", "share"), [
    (8.0, Roi(402, 155, 45, 199), 0.0220),
    (25.0, Roi(402, 197, 45, 97), 0.0107),
])
def test_roi_sizes_at_8_and_25_m_for_the_example_d435_calibration(x_m, roi, share):
    # The paper reports about 4.3 % and 1.3 % of the frame. Its column is a line, so the
    # box is 45 px wide at any range; with this calibration (fx 615, camera 1.3 m high,
    # 0.8 m behind the radar) the ROI is 2.2 % at 8 m and 1.07 % at 25 m. docs/fusion.md.
    got = roi_at(x_m, 0.0)
    assert got == roi
    assert got.area / FRAME_PIXELS == pytest.approx(share, abs=5e-5)


def test_a_wider_column_widens_the_roi():
    roi = roi_at(8.0, 0.0, half_width_m=0.3)
    half = 615.0 * 0.3 / 8.8                                                # 20.97 px
    assert roi.x == round(424 - half) - 22 and roi.w == 2 * round(half) + 45


def test_column_samples_with_distortion_match_the_radial_model_by_hand():
    k1, k2 = -0.1, 0.02
    cal = Calibration.from_matrices(848, 480, CAL.k, np.array([k1, k2, 0.0, 0.0, 0.0]),
                                    CAL.r, CAL.t)
    uv, valid = projector(cal).project_columns(np.array([[8.0, 1.0]]))
    assert valid.all() and uv.shape == (1, 5, 2)          # 5 samples when distorted
    for z, (u, v) in zip(np.linspace(0.0, 2.2, 5), uv[0], strict=True):
        xn, yn = -1.0 / 8.8, (1.3 - z) / 8.8
        r2 = xn * xn + yn * yn
        f = 1 + k1 * r2 + k2 * r2 * r2
        assert (u, v) == pytest.approx((424 + 615 * xn * f, 240 + 615 * yn * f), abs=1e-9)


def test_distortion_cannot_fold_a_point_far_outside_back_into_the_image():
    cal = Calibration.from_matrices(848, 480, CAL.k, np.array([-0.12, 0.0, 0.0, 0.0, 0.0]),
                                    CAL.r, CAL.t)
    # 5 m ahead, 17.4 m to the left: x/z = -3; the raw polynomial maps it inside.
    raw, _ = cal.project(np.array([[5.0, 17.4, 1.3]]))
    assert 0 <= raw[0, 0] < 848
    assert projector(cal).rois(np.array([[5.0, 17.4]])) == [None]


def test_tracks_behind_the_camera_or_outside_the_image_are_not_visible():
    rois = projector().rois(np.array([[-3.0, 0.0], [5.0, 20.0], [0.5, 0.0]]))
    assert rois[0] is None and rois[1] is None
    assert rois[2] == Roi(402, 0, 45, 480)            # very close: the whole height


def test_a_column_at_the_image_border_is_clipped():
    # u = 424 + 615 * 3.9 / 5.8 = 837.5 (y < 0 is right): 816 .. 860 is cut at 848.
    roi = roi_at(5.0, -3.9)
    assert (roi.x, roi.w) == (816, 32)


def test_fusion_predicts_the_track_to_the_frame_time_before_projecting():
    core = make_core()
    # The frame was captured 50 ms before the radar cycle: a track closing at 10 m/s and
    # moving left at 2 m/s was 0.5 m farther and 0.1 m more to the right then.
    frames = feed(frame(T0 - 50 * MS, seq=31))
    res = run(core, track(x=10.5, y=0.5, vx=-10.0, vy=2.0), frames=frames)
    tgt = res.targets.targets[0]
    assert (tgt.x_m, tgt.y_m) == pytest.approx((11.0, 0.4))
    assert tgt.frame_seq == 31 and tgt.frame_age_ms == pytest.approx(50.0)
    assert tuple(tgt.roi_xywh) == tuple(roi_at(11.0, 0.4))
    assert tgt.range_m == pytest.approx(np.hypot(10.5, 0.5))      # the decision's range
    assert tgt.verification is Verification.VERIFIED


def test_without_alignment_the_track_is_projected_where_the_radar_saw_it():
    core = make_core(frames={"align": False})
    res = run(core, track(x=10.5, y=0.5, vx=-10.0, vy=2.0), frames=feed(frame(T0 - 50 * MS)))
    tgt = res.targets.targets[0]
    assert (tgt.x_m, tgt.y_m) == (10.5, 0.5)
    assert tuple(tgt.roi_xywh) == tuple(roi_at(10.5, 0.5))
