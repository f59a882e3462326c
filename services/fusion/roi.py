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

from aeb_radar_camera.common.calibration import Calibration

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
        # Clip bounds of (x0, y0, x1, y1): x1, y1 are exclusive ends.
        self._size2 = np.array([self.width, self.height, self.width, self.height], float)
        self._last_px = np.array([self.width - 0.5, self.height - 0.5])
        r = calibration.r
        self._r0, self._r1 = r[:, 0], r[:, 1]
        self._sample_cam = (self._offsets[:, 0:1] * r[:, 1] + self._offsets[:, 1:2] * r[:, 2]
                            + calibration.t)

    def _normalised_limits(self) -> np.ndarray:
        """Largest |x/z| and |y/z| of the image's border pixels, undistorted."""
        w, h = self.width - 1, self.height - 1
        border = np.array([[0, 0], [w / 2, 0], [w, 0], [w, h / 2], [w, h], [w / 2, h],
                           [0, h], [0, h / 2]], dtype=np.float64).reshape(-1, 1, 2)
        norm = cv2.undistortPoints(border, self.cal.k, self.cal.dist).reshape(-1, 2)
        return np.abs(norm).max(axis=0)

    def project_columns(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels of every column sample: (uv (N, S, 2), valid (N, S)).

        A sample behind the camera is invalid (uv NaN). Samples far outside the image are
        clamped to a ray just outside it, so their pixels stay outside the image.
        """
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        n, s = len(xy), len(self._offsets)
        if n == 0:
            return np.empty((0, s, 2)), np.empty((0, s), bool)
        # X_cam = R (x, y + dy, z) + t = x R[:, 0] + y R[:, 1] + (dy R[:, 1] + z R[:, 2] + t):
        # the last term is the same for every track.
        cam = (xy[:, None, 0:1] * self._r0 + xy[:, None, 1:2] * self._r1
               + self._sample_cam).reshape(-1, 3)
        depth = cam[:, 2:3]
        valid = depth[:, 0] >= _MIN_DEPTH_M
        norm = cam[:, :2] / np.where(depth >= _MIN_DEPTH_M, depth, 1.0)
        np.clip(norm, -self._lim, self._lim, out=norm)
        rays = np.concatenate([norm, np.ones((len(norm), 1))], axis=1)
        proj, _ = cv2.projectPoints(rays.reshape(-1, 1, 3), self._zero, self._zero,
                                    self.cal.k, self.cal.dist)
        uv = proj.reshape(-1, 2)
        uv[~valid] = np.nan
        return uv.reshape(n, s, 2), valid.reshape(n, s)

    def rois(self, xy: np.ndarray) -> list[Roi | None]:
        """The padded, clipped ROI of each track's column; None when not visible (see
        `boxes`)."""
        return [b[0] if b is not None else None for b in self.boxes(xy)]

    def boxes(self, xy: np.ndarray) -> list[tuple[Roi, Roi] | None]:
        """(ROI, column) of each track: the column's own box (the pixels, nearest pixel
        centre, of its samples, clipped to the image) and the ROI, that box plus
        `padding_px` on every side, clipped; None when not visible (behind the camera,
        or the unpadded column does not touch the image)."""
        uv, valid = self.project_columns(xy)
        if len(uv) == 0:
            return []
        lo = np.min(uv, axis=1, initial=np.inf, where=valid[:, :, None])
        hi = np.max(uv, axis=1, initial=-np.inf, where=valid[:, :, None])
        visible = (valid.any(axis=1) & (hi > -0.5).all(axis=1)
                   & (lo < self._last_px).all(axis=1))
        pad = self.geometry.padding_px
        column = np.concatenate([lo, hi], axis=1)
        column[~visible] = 0.0
        column = np.floor(column + 0.5)
        column[:, 2:] += 1
        box = column.copy()
        box[:, :2] -= pad
        box[:, 2:] += pad
        np.clip(box, 0, self._size2, out=box)
        np.clip(column, 0, self._size2, out=column)
        out: list[tuple[Roi, Roi] | None] = []
        for (x0, y0, x1, y1), (c0, r0, c1, r1), vis in zip(
                box.astype(np.int64).tolist(), column.astype(np.int64).tolist(),
                visible.tolist(), strict=True):
            out.append((Roi(x0, y0, x1 - x0, y1 - y0), Roi(c0, r0, c1 - c0, r1 - r0))
                       if vis else None)
        return out
