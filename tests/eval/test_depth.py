"""Depth images from points and the D435 noise model."""

import numpy as np
import pytest

from aeb_radar_camera.tools.eval.depth import D435Noise, project_depth

K = np.array([[100.0, 0.0, 20.0], [0.0, 100.0, 10.0], [0.0, 0.0, 1.0]])


def test_the_nearest_point_of_each_pixel_and_zero_where_none():
    pts = np.array([[0.0, 0.0, 10.0], [0.0, 0.0, 4.0], [0.001, 0.0, 12.0],  # one pixel
                    [1.0, 0.5, 5.0],                                        # u 40: outside
                    [0.5, 0.2, 5.0], [0.0, 0.0, -3.0]])                     # behind
    d = project_depth(pts, K, 40, 20)
    assert d.dtype == np.float32 and d.shape == (20, 40)
    assert d[10, 20] == 4.0
    assert d[14, 30] == 5.0
    assert np.count_nonzero(d) == 2


def test_d435_rms_grows_with_distance_squared_per_intels_formula():
    model = D435Noise(focal_px=449.0, baseline_m=0.05, subpixel=0.08, hole_rate=0.0)
    assert model.rms_m(10.0) == pytest.approx(100 * 0.08 / (449 * 0.05))
    rng = np.random.default_rng(0)
    depth = np.full((200, 200), 10.0, np.float32)
    depth[100:] = 20.0
    noisy = model.apply(depth, rng)
    near, far = noisy[:100] - 10.0, noisy[100:] - 20.0
    assert near.std() == pytest.approx(model.rms_m(10.0), rel=0.05)
    assert far.std() / near.std() == pytest.approx(4.0, rel=0.08)
    assert abs(near.mean()) < 0.02
    # Reported in 1 mm units.
    assert np.allclose(noisy * 1000, np.round(noisy * 1000), atol=1e-2)


def test_d435_gaps_minimum_range_holes_and_no_data_stay_zero():
    model = D435Noise(hole_rate=0.1)
    assert model.min_depth_m == pytest.approx(449 * 0.05 / 126)
    depth = np.zeros((100, 100), np.float32)
    depth[:50] = 5.0
    depth[50:60] = 0.1                       # closer than the minimum distance
    out = model.apply(depth, np.random.default_rng(1))
    assert np.all(out[60:] == 0) and np.all(out[50:60] == 0)
    holes = np.mean(out[:50] == 0)
    assert 0.07 < holes < 0.13
    with pytest.raises(ValueError):
        D435Noise(hole_rate=1.0)
