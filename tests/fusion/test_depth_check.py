"""The depth verifier on synthetic depth images: an obstacle at the track's range passes;
an empty column, road only, something overhead only, or a surface at another range
fails; missing depth is not applicable."""

import numpy as np
import pytest

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.depth_error import D435Noise
from aeb_radar_camera.services.fusion.roi import ColumnGeometry, ColumnProjector
from aeb_radar_camera.services.fusion.verifiers import Observation, VerifierConfigError, create
from aeb_radar_camera.services.fusion.verifiers.depth import DepthConsistency, DepthParams
from aeb_radar_camera.tools.eval.depth import Box, box_scene_depth, car_box
from tests.fusion.helpers import CAL

PAPER = ColumnProjector(CAL, ColumnGeometry())                 # the one-pixel column
WIDE = ColumnProjector(CAL, ColumnGeometry(half_width_m=0.54))  # the evaluation's


def render_depth(cal: Calibration, road: bool = True, boxes: tuple[Box, ...] = ()
                 ) -> np.ndarray:
    return box_scene_depth(cal, boxes, road)


def observe(depth: np.ndarray | None, x: float, y: float = 0.0,
            projector: ColumnProjector = PAPER) -> Observation:
    got = projector.boxes(np.array([[x, y]]))[0]
    assert got is not None
    roi, column = got
    gray = np.zeros((CAL.height, CAL.width), np.uint8)
    return Observation(gray, roi, column, float(np.hypot(x, y)), depth, CAL, (x, y))


car = car_box


VERIFIER = create("depth")


@pytest.mark.parametrize("x", [4.0, 10.0, 20.0])
@pytest.mark.parametrize("projector", [PAPER, WIDE])
def test_an_obstacle_at_the_range_passes_and_the_road_alone_fails(x, projector):
    with_car = VERIFIER.verify(observe(render_depth(CAL, boxes=(car(x),)), x,
                                       projector=projector))
    road = VERIFIER.verify(observe(render_depth(CAL), x, projector=projector))
    assert with_car.verified and with_car.score > 0.8, with_car
    assert not road.verified and road.score < 0.05, road


def test_an_empty_column_fails_with_zero_returns():
    got = VERIFIER.verify(observe(render_depth(CAL, road=False), 10.0))
    assert got.score == 0.0 and not got.verified and got.detail["returns"] == 0


def test_something_overhead_only_fails():
    sign = (12.0, 12.3, -2.0, 2.0, 4.5, 5.5)          # a gantry sign 4.5 m up
    depth = render_depth(CAL, boxes=(sign,))
    obs = observe(depth, 12.0)
    assert np.any(depth[obs.roi.y:obs.roi.y + obs.roi.h] > 0)
    got = VERIFIER.verify(obs)
    assert not got.verified and got.score < 0.05, got


def test_a_surface_at_another_range_fails():
    # A plate on the road at 10 m with a car 6 m further on.
    got = VERIFIER.verify(observe(render_depth(CAL, boxes=(car(16.0),)), 10.0))
    assert not got.verified, got
    # And a car nearer than the track hides it: nearer, not at the range.
    near = VERIFIER.verify(observe(render_depth(CAL, boxes=(car(5.0),)), 10.0))
    assert not near.verified and near.detail["nearer"] > 0.5, near


def test_off_axis_the_range_is_compared_with_distance_not_camera_z():
    # At 35 deg off the axis camera z is 18% short of the distance.
    x, y = 8.0, 5.6
    got = VERIFIER.verify(observe(render_depth(CAL, boxes=(car(x, y),)), x, y))
    assert got.verified and got.score > 0.8, got


def test_tolerance_follows_the_d435_model_and_noise_within_it_still_passes():
    v = DepthConsistency(DepthParams())
    model = D435Noise()
    for r in (3.0, 10.0, 25.0):
        assert v.tolerance_m(r) == pytest.approx(2.0 * float(model.rms_m(r)) + 0.3)
    x = 20.0
    depth = model.apply(render_depth(CAL, boxes=(car(x),)), np.random.default_rng(3))
    got = v.verify(observe(depth, x))
    assert got.verified and got.score > 0.8, got


def test_sparse_depth_counts_only_pixels_with_a_return():
    depth = render_depth(CAL, boxes=(car(10.0),))
    sparse = np.zeros_like(depth)
    sparse[::4] = depth[::4]                           # every 4th row: lidar lines
    dense_score = VERIFIER.verify(observe(depth, 10.0)).score
    assert VERIFIER.verify(observe(sparse, 10.0)).score == pytest.approx(dense_score, abs=0.05)


def test_missing_depth_or_geometry_is_an_error_and_bad_params_are_refused():
    obs = observe(None, 10.0)
    assert VERIFIER.needs_depth
    with pytest.raises(ValueError, match="needs depth_m"):
        VERIFIER.verify(obs)
    with pytest.raises(VerifierConfigError):
        create("depth", {"min_height_m": 3.0})
    with pytest.raises(VerifierConfigError):
        create("depth", {"tau": 2.0})
    assert create("depth", {"tau": 0.3}).params()["tau"] == 0.3


def test_known_limit_a_wall_or_rail_at_the_range_passes_like_an_obstacle():
    # Depth confirms what really stands at the range: a wall along the road's edge and a
    # guard rail 0.3-0.8 m high (a radar return off either is a real surface).
    wall = (5.0, 40.0, 3.0, 3.3, 0.0, 2.5)
    rail = (5.0, 40.0, -3.3, -3.0, 0.3, 0.8)
    depth = render_depth(CAL, boxes=(wall, rail))
    assert VERIFIER.verify(observe(depth, 12.0, 3.0)).verified
    assert VERIFIER.verify(observe(depth, 12.0, -3.0)).verified


def test_ray_maps_are_shared_by_calibrations_that_differ_only_in_t_and_undistort():
    from aeb_radar_camera.services.fusion.verifiers import depth as depth_check

    raised = Calibration.from_matrices(CAL.width, CAL.height, CAL.k, CAL.dist, CAL.r,
                                       CAL.t + np.array([0.0, 0.3, 0.0]))
    assert depth_check.ray_maps(raised) is depth_check.ray_maps(CAL)
    # A distorted camera: each pixel's ray is cv2.undistortPoints' (a small image).
    import cv2

    k = np.array([[60.0, 0.0, 32.0], [0.0, 60.0, 24.0], [0.0, 0.0, 1.0]])
    dist = np.array([-0.3, 0.1, 0.0, 0.0, 0.0])
    bent = Calibration.from_matrices(64, 48, k, dist, CAL.r, CAL.t)
    maps = depth_check.ray_maps(bent)
    for u, v in ((0, 0), (63, 47), (40, 10)):
        xn, yn = cv2.undistortPoints(np.array([[[u, v]]], np.float64), k, dist)[0, 0]
        ray = CAL.r.T @ np.array([xn, yn, 1.0])
        assert maps.run[v, u] == pytest.approx(np.hypot(ray[0], ray[1]), rel=1e-5)
        assert maps.rise[v, u] == pytest.approx(ray[2], rel=1e-5, abs=1e-6)


def test_fusion_prepares_the_verifier_for_each_cameras_calibration():
    from tests.fusion.helpers import make_core

    seen = []

    class Preparing(DepthConsistency):
        def prepare(self, calibration: Calibration) -> None:
            seen.append(calibration)
            super().prepare(calibration)

    core = make_core(Preparing(DepthParams()))
    assert seen == [core.cameras[0].projector.cal]
