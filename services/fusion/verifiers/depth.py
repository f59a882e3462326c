"""The depth verifier (`depth`): does a surface stand in the track's column at the radar's range?

A real obstacle fills part of the column 0.3-2.2 m above the ground at the track's range;
a radar false target - metal on the road (a plate, a manhole cover), a sign overhead, a
multipath ghost - leaves that part of the column empty at that range: the depth there is
the road behind, the sky, or nothing.

Each pixel of the window (the ROI's rows; the column box's columns, widened to
`min_width_px` for the paper's one-pixel column) is a ray of the calibration. A pixel is
in the band when its ray, at the track's distance from the camera, lies `min_height_m` to
`max_height_m` above the ground; it is a hit when its measured depth puts its 3-D point
in that band (height from its own depth: the road seen through the band's rows lies at
height 0 whatever its distance, and a clipped column or a tilted camera does not move the
band) at a horizontal distance from the camera d with

    r - tol(r) <= d <= r + tol(r) + extent_m
    tol(r) = k_sigma * rms(r) + margin_m,  rms(r) = r^2 * subpixel / (f_px * baseline)

r the track's distance from the camera, rms the D435's RMS depth error after Intel's
white paper "Tuning depth cameras for best performance" (common/depth_error.py, the same
model the evaluation applies to lidar depth); `margin_m` covers the radar's range error,
`extent_m` the obstacle's visible surfaces behind its nearest point (a car's side, roof
and rear window: at 5 m they fill much of the column 1-3 m behind the bumper).

    score = hits / band pixels with a return

(0 when fewer than `min_returns` band pixels have a return: nothing there to confirm),
verified iff score >= tau. Pixels without a return (0) count neither way, so the
score means the same on a dense D435 image and on sparse lidar depth. Each pixel's ray
(distortion removed) comes from maps computed once per calibration (`ray_maps`; `prepare`
computes them ahead, e.g. when fusion starts, so that no radar cycle waits for them).

What depth cannot tell: a structure that is really there at the range - a guard rail, a
wall, a pole, a tree - fills the band like an obstacle does; the appearance verifiers
judge those.
"""

import threading
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated

import cv2
import msgspec
import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.depth_error import D435Noise
from aeb_radar_camera.services.fusion.verifiers.base import (
    GateResult,
    Observation,
    ParamValue,
    Verifier,
    parse_params,
)

SCORE = "depth_share"        # hits / band pixels with a return
Metres = Annotated[float, msgspec.Meta(ge=0, le=100)]
# Depth at or below this (metres) is "no return" (0); also the strictness of "nearer".
NO_RETURN_M = 1e-6


class DepthParams(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    tau: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.15
    min_height_m: Metres = 0.3
    max_height_m: Metres = 2.2
    k_sigma: Annotated[float, msgspec.Meta(ge=0, le=10)] = 2.0
    margin_m: Metres = 0.3
    extent_m: Metres = 1.0
    # The depth camera's model (the D435 at 848x480).
    focal_px: Annotated[float, msgspec.Meta(gt=0, le=10000)] = 449.0
    baseline_m: Annotated[float, msgspec.Meta(gt=0, le=1)] = 0.050
    subpixel: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.08
    min_width_px: Annotated[int, msgspec.Meta(ge=1, le=1000)] = 24
    min_returns: Annotated[int, msgspec.Meta(ge=1, le=100000)] = 8

    def __post_init__(self) -> None:
        if self.min_height_m >= self.max_height_m:
            raise ValueError("min_height_m must be below max_height_m")


def _window_cols(obs: Observation, min_width: int, image_width: int) -> tuple[int, int]:
    """Columns [c0, c1) of the window: the column box's, widened about its centre to
    `min_width` within the image."""
    col = obs.column
    c0, c1 = col.x, col.x + col.w
    if c1 - c0 < min_width:
        mid = (c0 + c1) / 2.0
        c0 = round(mid - min_width / 2.0)
        c1 = c0 + min_width
    return max(c0, 0), min(c1, image_width)


@dataclass(frozen=True)
class RayMaps:
    """Per pixel of a calibration's image, its ray in the ground frame per unit of camera
    depth (R^T (x/z, y/z, 1), distortion removed): horizontal `run`, `rise`, and
    `slope` = rise / run, and `side`, its sideways component (the ground frame's y, left
    positive) (float32, height x width)."""

    run: np.ndarray
    rise: np.ndarray
    slope: np.ndarray
    side: np.ndarray


def _key(cal: Calibration) -> bytes:
    # The rays depend on the image size, K, the distortion and R, not on t: the
    # evaluation's calibrations that differ only in the ground's height share them.
    return b"".join((np.array([cal.width, cal.height], np.int64).tobytes(),
                     np.asarray(cal.k, np.float64).tobytes(),
                     np.asarray(cal.dist, np.float64).tobytes(),
                     np.asarray(cal.r, np.float64).tobytes()))


def ray_maps(cal: Calibration) -> RayMaps:
    """The calibration's RayMaps, computed once per (size, K, distortion, R) and kept for
    the last `_MAPS` of them (each 4 x 4 bytes per pixel: 6.5 MB at 848x480)."""
    key = _key(cal)
    with _MAPS_LOCK:
        got = _MAPS_CACHE.get(key)
        if got is not None:
            _MAPS_CACHE.move_to_end(key)
            return got
    maps = _compute_maps(cal)
    with _MAPS_LOCK:
        _MAPS_CACHE[key] = maps
        while len(_MAPS_CACHE) > _MAPS:
            _MAPS_CACHE.popitem(last=False)
    return maps


def _compute_maps(cal: Calibration) -> RayMaps:
    k, w, h = cal.k, cal.width, cal.height
    if not np.any(cal.dist):
        yn = ((np.arange(h, dtype=np.float64) - k[1, 2]) / k[1, 1])[:, None]
        xn = (np.arange(w, dtype=np.float64)[None, :] - k[0, 2] - k[0, 1] * yn) / k[0, 0]
        yn = np.broadcast_to(yn, xn.shape)
    else:
        v, u = np.mgrid[0:h, 0:w].astype(np.float64)
        pts = np.stack([u.ravel(), v.ravel()], axis=-1).reshape(-1, 1, 2)
        norm = cv2.undistortPoints(pts, k, cal.dist).reshape(h, w, 2)
        xn, yn = norm[..., 0], norm[..., 1]
    r = cal.r
    side = r[0, 1] * xn + r[1, 1] * yn + r[2, 1]
    run = np.hypot(r[0, 0] * xn + r[1, 0] * yn + r[2, 0], side)
    rise = r[0, 2] * xn + r[1, 2] * yn + r[2, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(run > 1e-9, rise / run, np.inf)
    return RayMaps(run.astype(np.float32), rise.astype(np.float32), slope.astype(np.float32),
                   side.astype(np.float32))


_MAPS = 8
_MAPS_CACHE: OrderedDict[bytes, RayMaps] = OrderedDict()
_MAPS_LOCK = threading.Lock()


class DepthConsistency:
    """The depth verifier (module docstring)."""

    name = "depth"
    needs_depth = True

    def __init__(self, p: DepthParams) -> None:
        self.p = p
        self.model = D435Noise(focal_px=p.focal_px, baseline_m=p.baseline_m,
                               subpixel=p.subpixel, hole_rate=0.0)

    def params(self) -> dict[str, ParamValue]:
        return msgspec.structs.asdict(self.p)

    def prepare(self, calibration: Calibration) -> None:
        """Compute the calibration's ray maps now rather than in the first verify()."""
        ray_maps(calibration)

    def tolerance_m(self, distance_m: float) -> float:
        return float(self.p.k_sigma * self.model.rms_m(distance_m) + self.p.margin_m)

    def verify(self, obs: Observation) -> GateResult:
        """Raises ValueError when the observation lacks depth, calibration or xy_m
        (fusion and the evaluation give all three to a verifier that needs depth)."""
        p = self.p
        col = column_depth(obs, p.min_width_px, p.min_height_m, p.max_height_m)
        expected = col.expected_m
        tol = self.tolerance_m(expected)
        n_returns = cv2.countNonZero(col.returns)
        at = cv2.inRange(col.dist, expected - tol, expected + tol + p.extent_m)
        high = cv2.inRange(col.lift, p.min_height_m - col.camera_z_m,
                           p.max_height_m - col.camera_z_m)
        n_hit = cv2.countNonZero(cv2.bitwise_and(cv2.bitwise_and(col.returns, at), high))
        near = cv2.countNonZero(cv2.bitwise_and(
            col.returns, cv2.inRange(col.dist, -np.inf, expected - tol - NO_RETURN_M)))
        score = n_hit / n_returns if n_returns >= p.min_returns else 0.0
        return GateResult(score, score >= p.tau,
                          {"returns": float(n_returns), "hits": float(n_hit),
                           "nearer": near / n_returns if n_returns else 0.0,
                           "expected_m": expected, "tol_m": tol}, SCORE)


@dataclass(frozen=True, slots=True)
class ColumnDepth:
    """A track's column window seen in depth, in the ground frame. Per pixel of the
    window (float32 / uint8 masks of 255, window-sized): `depth` the camera depth, `dist`
    the measured point's horizontal distance from the camera, `lift` its height above the
    camera, `band` the pixels whose ray at the track's distance lies in the height band
    asked for, `returns` those of them with a depth return; `run`, `side`, `slope` the
    window's part of the RayMaps, `maps` the whole image's. `expected_m`: the track's
    distance from the camera; `camera_y_m`, `camera_z_m`: the camera's sideways position
    and height in the ground frame."""

    depth: np.ndarray
    dist: np.ndarray
    lift: np.ndarray
    band: np.ndarray
    returns: np.ndarray
    run: np.ndarray
    side: np.ndarray
    slope: np.ndarray
    maps: RayMaps
    expected_m: float
    camera_y_m: float
    camera_z_m: float

    # Asked only where depth confirms an object (its extent): not paid for every window.
    def across(self) -> np.ndarray:
        """Per pixel, the measured point's sideways offset from the camera (ground y,
        left positive)."""
        return cv2.multiply(self.depth, self.side)

    def ray_across(self) -> np.ndarray:
        """Per pixel, the sideways offset of its ray at the track's distance: where the
        window lies at the range."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.run > 1e-9, self.side * np.float32(self.expected_m)
                            / self.run, np.float32(0.0)).astype(np.float32)


def column_depth(obs: Observation, min_width_px: int, band_min_m: float,
                 band_max_m: float, half_width_m: float = 0.0) -> ColumnDepth:
    """The column window of `obs` in depth (see ColumnDepth): the ROI's rows, the column
    box's columns widened to `min_width_px`, and to `half_width_m` either side at the
    track's distance; the band `band_min_m`..`band_max_m` above the ground at the track.
    Raises ValueError when the observation lacks depth, calibration or xy_m."""
    if obs.depth_m is None or obs.calibration is None or obs.xy_m is None:
        raise ValueError("the depth verifier needs depth_m, calibration and xy_m")
    cal, roi = obs.calibration, obs.roi
    # The camera's centre in the ground frame, and the track's distance from it.
    centre = -cal.r.T @ cal.t
    expected = float(np.hypot(obs.xy_m[0] - centre[0], obs.xy_m[1] - centre[1]))
    width = max(min_width_px, round(2.0 * half_width_m * float(cal.k[0, 0])
                                    / max(expected, 0.1)))
    c0, c1 = _window_cols(obs, width, obs.depth_m.shape[1])
    r0, r1 = roi.y, roi.y + roi.h
    maps = ray_maps(cal)
    cz = float(centre[2])
    d = obs.depth_m[r0:r1, c0:c1]
    if d.dtype != np.float32:
        d = d.astype(np.float32)
    # In the band: the ray at the track's distance stands min..max height above the
    # ground, i.e. rise / run within [(min - cz) / r, (max - cz) / r].
    slope = maps.slope[r0:r1, c0:c1]
    band = cv2.inRange(slope, (band_min_m - cz) / expected, (band_max_m - cz) / expected)
    returns = cv2.bitwise_and(band, cv2.inRange(d, NO_RETURN_M, np.inf))
    run = maps.run[r0:r1, c0:c1]
    dist = cv2.multiply(d, run)
    lift = cv2.multiply(d, maps.rise[r0:r1, c0:c1])   # height above the camera
    return ColumnDepth(d, dist, lift, band, returns, run, maps.side[r0:r1, c0:c1], slope, maps,
                       expected, float(centre[1]), cz)


def make(params: Mapping[str, ParamValue]) -> Verifier:
    return DepthConsistency(parse_params(params, DepthParams, "depth"))
