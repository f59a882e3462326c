"""The RealSense D435's depth error: one model for fusion's depth verifier (its
tolerance) and for the evaluation (noise applied to lidar depth).

From Intel's white paper "Tuning depth cameras for best performance" (RealSense D400
series; also the D400 datasheet's depth RMS error): the RMS depth error of a stereo
camera grows with the square of the distance,

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


@dataclass(frozen=True)
class D435Noise:
    """The D435's depth error and gaps (module docstring). Raises ValueError on a
    non-positive focal length or baseline, a negative subpixel or a hole rate outside
    [0, 1)."""

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
