"""Depth images aligned to the camera from lidar points, and a model of the RealSense
D435's depth error to apply to them.

`project_depth` gives the depth (camera z, metres) of the nearest point in each pixel,
0 where no point falls: a lidar's depth image is sparse (64 lines), a D435's is dense;
verifiers that read depth get 0 as "no return" in both.

The D435 model (`D435Noise`), from Intel's white paper "Tuning depth cameras for best
performance" (RealSense D400 series): the RMS depth error of a stereo camera grows with
the square of the distance,

    rms(z) = z^2 * subpixel / (f_px * baseline)

with the D435's 50 mm baseline, a subpixel accuracy of about 0.08 (Intel quotes 0.05-0.1
for textured scenes) and f_px the depth stream's focal length in pixels (about 420-450 at
848x480: its 87 x 58 deg field of view); 0.36 m at 10 m, 2.2 m at 25 m with f 449 px.
Depth is reported in 1 mm units up to 65.535 m. No depth closer than the minimum
distance, where the disparity exceeds the search range of 126 px: min_z = f_px *
baseline / 126 (0.18 m at 449 px). Holes (no depth: low texture, occlusion edges) are
drawn at random at `hole_rate`.
"""

from dataclasses import dataclass

import numpy as np

DISPARITY_SEARCH_PX = 126
MAX_DEPTH_M = 65.535        # uint16 depth in 1 mm units


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


@dataclass(frozen=True)
class D435Noise:
    """The D435's depth error and gaps (module docstring)."""

    focal_px: float = 449.0
    baseline_m: float = 0.050
    subpixel: float = 0.08
    hole_rate: float = 0.02
    max_depth_m: float = MAX_DEPTH_M

    def __post_init__(self) -> None:
        if self.focal_px <= 0 or self.baseline_m <= 0 or self.subpixel < 0:
            raise ValueError("focal_px and baseline_m must be positive, subpixel >= 0")
        if not 0 <= self.hole_rate < 1:
            raise ValueError("hole_rate must be in [0, 1)")

    @property
    def min_depth_m(self) -> float:
        return self.focal_px * self.baseline_m / DISPARITY_SEARCH_PX

    def rms_m(self, z: np.ndarray | float) -> np.ndarray:
        return np.asarray(z, dtype=np.float64) ** 2 * self.subpixel / (
            self.focal_px * self.baseline_m)

    def apply(self, depth: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """A copy of `depth` (0 = none) as a D435 would report it."""
        out = depth.astype(np.float64)
        valid = out > 0
        z = out[valid]
        z = z + rng.standard_normal(len(z)) * self.rms_m(z)
        z = np.round(z * 1000.0) / 1000.0
        z[(z < self.min_depth_m) | (z > self.max_depth_m)] = 0.0
        if self.hole_rate > 0:
            z[rng.random(len(z)) < self.hole_rate] = 0.0
        out[valid] = z
        return out.astype(np.float32)
