"""Depth images aligned to the camera from lidar points or from a box scene, and a
model of the RealSense D435's depth error to apply to them.

`project_depth` gives the depth (camera z, metres) of the nearest point in each pixel,
0 where no point falls: a lidar's depth image is sparse (64 lines), a D435's is dense;
verifiers that read depth get 0 as "no return" in both. `box_scene_depth` ray-casts a
dense depth image of a flat road and axis-aligned boxes (a SIMULATION, for tests and
benchmarks of the depth path).

The D435 model (`D435Noise`) lives in common/depth_error.py: fusion's depth verifier
takes its tolerance from the same model.
"""

import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.depth_error import D435Noise

__all__ = ["D435Noise", "box_scene_depth", "car_box", "project_depth"]


def project_depth(points_cam: np.ndarray, k: np.ndarray, width: int, height: int,
                  min_depth_m: float = 0.1) -> np.ndarray:
    """(N, 3) camera-frame points to a float32 (height, width) depth image: the nearest
    point per pixel (pixel centres at integer coordinates), 0 where none."""
    depth = np.zeros((height, width), np.float32)
    pts = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
    pts = pts[pts[:, 2] >= min_depth_m]
    if len(pts) == 0:
        return depth
    uvw = pts @ k.T
    u = np.floor(uvw[:, 0] / uvw[:, 2] + 0.5).astype(np.int64)
    v = np.floor(uvw[:, 1] / uvw[:, 2] + 0.5).astype(np.int64)
    inside = (u >= 0) & (u < width) & (v >= 0) & (v < height)
    u, v, z = u[inside], v[inside], pts[inside, 2]
    # Far first: where two points share a pixel, the nearer one is written last.
    order = np.argsort(-z, kind="stable")
    depth[v[order], u[order]] = z[order]
    return depth


Box = tuple[float, float, float, float, float, float]   # x0, x1, y0, y1, z0, z1 (ground)


def box_scene_depth(cal: Calibration, boxes: tuple[Box, ...] = (), road: bool = True,
                    max_range_m: float = 80.0) -> np.ndarray:
    """Camera z of the nearest surface per pixel (float32, 0 where none within
    `max_range_m`): the road plane z = 0 of the calibration's ground frame and
    axis-aligned boxes of it. Pinhole: raises ValueError for a distorted calibration."""
    if np.any(cal.dist):
        raise ValueError("box_scene_depth needs an undistorted calibration")
    v, u = np.mgrid[0:cal.height, 0:cal.width].astype(np.float64)
    k = cal.k
    cam = np.stack([(u - k[0, 2]) / k[0, 0], (v - k[1, 2]) / k[1, 1], np.ones_like(u)], -1)
    ray = cam @ cal.r                 # R^T per pixel: the ray in the ground frame per unit z
    c = -cal.r.T @ cal.t
    best = np.full(ray.shape[:2], np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        if road:
            s = -c[2] / ray[..., 2]
            best = np.where((s > 0) & (s < max_range_m), s, best)
        for box in boxes:
            lo = np.full(best.shape, -np.inf)
            hi = np.full(best.shape, np.inf)
            for axis in range(3):
                t0 = (box[2 * axis] - c[axis]) / ray[..., axis]
                t1 = (box[2 * axis + 1] - c[axis]) / ray[..., axis]
                lo = np.maximum(lo, np.minimum(t0, t1))
                hi = np.minimum(hi, np.maximum(t0, t1))
            hit = (hi >= lo) & (lo > 0) & (lo < best)
            best = np.where(hit, lo, best)
    return np.where(np.isfinite(best), best, 0.0).astype(np.float32)


def car_box(x: float, y: float = 0.0) -> Box:
    """A car-sized box whose rear is at x (1.8 m wide, 0.2-1.5 m above the road)."""
    return (x, x + 4.0, y - 0.9, y + 0.9, 0.2, 1.5)
