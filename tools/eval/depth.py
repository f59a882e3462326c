"""Depth images aligned to the camera from lidar points, and a model of the RealSense
D435's depth error to apply to them.

`project_depth` gives the depth (camera z, metres) of the nearest point in each pixel,
0 where no point falls: a lidar's depth image is sparse (64 lines), a D435's is dense;
verifiers that read depth get 0 as "no return" in both.

The D435 model (`D435Noise`) lives in common/depth_error.py: fusion's depth verifier
takes its tolerance from the same model.
"""

import numpy as np

from common.depth_error import D435Noise

__all__ = ["D435Noise", "project_depth"]


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
