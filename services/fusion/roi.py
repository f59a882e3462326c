"""Project radar tracks as the paper's column and build their ROIs (pure, no I/O).

The column is z in [0, column_height_m] standing on the ground at the track's (x, y) in
the radar ground frame (common/calibration.py). It is sampled, projected with K, R, t and
distortion, boxed, padded and clipped to the image. Fusion and `aeb calib-check` both use
`ColumnProjector`, so that what a person checks is what fusion verifies.
"""

from dataclasses import dataclass
from typing import NamedTuple

import cv2
import numpy as np

from common.calibration import Calibration

# Samples along the column: with distortion the projected column is a curve whose extreme
# pixel can lie between its end points.
_SAMPLES_DISTORTED = 5
# Points behind this depth (camera frame, metres) are behind the camera.
_MIN_DEPTH_M = 0.1
# Normalised image-plane coordinates are clamped to this multiple of the image's own
# extent before distortion: the distortion polynomial folds back far outside the image,
# which would mirror an invisible point into the frame.
_FOV_MARGIN = 1.5


class Roi(NamedTuple):
    """A pixel box inside the image: columns x..x+w-1, rows y..y+h-1."""

    x: int
    y: int
    w: int
    h: int

    @property
    def area(self) -> int:
        return self.w * self.h


@dataclass(frozen=True)
class ColumnGeometry:
    height_m: float = 2.2
    half_width_m: float = 0.0   # 0: a vertical line (the paper); > 0: a box of that width
    padding_px: int = 22


class ColumnProjector:
    """Projects many tracks' columns in one OpenCV call."""

    def __init__(self, calibration: Calibration, geometry: ColumnGeometry) -> None:
        self.cal = calibration
        self.geometry = geometry
        self.width = calibration.width
        self.height = calibration.height
        distorted = bool(np.any(calibration.dist != 0))
        n_z = _SAMPLES_DISTORTED if distorted else 2
        zs = np.linspace(0.0, geometry.height_m, n_z)
        ys = [0.0] if geometry.half_width_m == 0 else [-geometry.half_width_m,
                                                        geometry.half_width_m]
        # Offsets (dy, z) of every sample of one column.
        self._offsets = np.array([(dy, z) for dy in ys for z in zs])
        self._lim = self._normalised_limits() * _FOV_MARGIN
        self._zero = np.zeros(3)

    def _normalised_limits(self) -> np.ndarray:
        """Largest |x/z| and |y/z| of the image's border pixels, undistorted."""
        w, h = self.width - 1, self.height - 1
        border = np.array([[0, 0], [w / 2, 0], [w, 0], [w, h / 2], [w, h], [w / 2, h],
                           [0, h], [0, h / 2]], dtype=np.float64).reshape(-1, 1, 2)
        norm = cv2.undistortPoints(border, self.cal.k, self.cal.dist).reshape(-1, 2)
        return np.abs(norm).max(axis=0)

    def column_points(self, xy: np.ndarray) -> np.ndarray:
        """(N, S, 3) ground-frame samples of the columns at (N, 2) track positions."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        pts = np.empty((len(xy), len(self._offsets), 3))
        pts[:, :, 0] = xy[:, None, 0]
        pts[:, :, 1] = xy[:, None, 1] + self._offsets[None, :, 0]
        pts[:, :, 2] = self._offsets[None, :, 1]
        return pts

    def project_columns(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels of every column sample: (uv (N, S, 2), valid (N, S)).

        A sample behind the camera is invalid (uv NaN). Samples far outside the image are
        clamped to a ray just outside it, so their pixels stay outside the image.
        """
        pts = self.column_points(xy)
        n, s, _ = pts.shape
        cam = self.cal.to_camera(pts.reshape(-1, 3))
        valid = cam[:, 2] >= _MIN_DEPTH_M
        uv = np.full((n * s, 2), np.nan)
        if valid.any():
            front = cam[valid]
            norm = front[:, :2] / front[:, 2:3]
            np.clip(norm, -self._lim, self._lim, out=norm)
            rays = np.concatenate([norm, np.ones((len(norm), 1))], axis=1)
            proj, _ = cv2.projectPoints(rays.reshape(-1, 1, 3), self._zero, self._zero,
                                        self.cal.k, self.cal.dist)
            uv[valid] = proj.reshape(-1, 2)
        return uv.reshape(n, s, 2), valid.reshape(n, s)

    def rois(self, xy: np.ndarray) -> list[Roi | None]:
        """The padded, clipped ROI of each track's column; None when not visible (behind
        the camera, or the unpadded column does not touch the image).

        The box spans the pixels (nearest pixel centre) of the column's samples, plus
        `padding_px` on every side, clipped to the image.
        """
        uv, valid = self.project_columns(xy)
        if len(uv) == 0:
            return []
        u, v = uv[:, :, 0], uv[:, :, 1]
        umin = np.min(u, axis=1, initial=np.inf, where=valid)
        umax = np.max(u, axis=1, initial=-np.inf, where=valid)
        vmin = np.min(v, axis=1, initial=np.inf, where=valid)
        vmax = np.max(v, axis=1, initial=-np.inf, where=valid)
        visible = (valid.any(axis=1) & (umax > -0.5) & (vmax > -0.5)
                   & (umin < self.width - 0.5) & (vmin < self.height - 0.5))
        pad = self.geometry.padding_px
        # Only visible rows are converted: the others hold infinities.
        rows = np.flatnonzero(visible)
        out: list[Roi | None] = [None] * len(uv)
        if len(rows):
            x0 = np.maximum(0, np.floor(umin[rows] + 0.5).astype(np.int64) - pad)
            y0 = np.maximum(0, np.floor(vmin[rows] + 0.5).astype(np.int64) - pad)
            x1 = np.minimum(self.width, np.floor(umax[rows] + 0.5).astype(np.int64) + pad + 1)
            y1 = np.minimum(self.height, np.floor(vmax[rows] + 0.5).astype(np.int64) + pad + 1)
            for j, i in enumerate(rows.tolist()):
                out[i] = Roi(int(x0[j]), int(y0[j]), int(x1[j] - x0[j]), int(y1[j] - y0[j]))
        return out


def predict_xy(x_m: float, y_m: float, vx_mps: float, vy_mps: float,
               dt_s: float) -> tuple[float, float]:
    """Constant-velocity prediction of a track over dt_s (negative: into the past)."""
    return x_m + vx_mps * dt_s, y_m + vy_mps * dt_s
