"""The paper's ROIs on a data set's frame, at the paper's pixel scale (pure).

Positives: every labelled object of the chosen classes whose nearest point is 3-25 m
from the camera gets the paper's column - 0 to 2.2 m high, standing on the object's
ground at that nearest point - projected, boxed and padded by fusion's own
ColumnProjector, in the image resampled so that its focal length is the paper's camera's
(`focal_px`): a 22 px padding then covers what it covered on the paper's 848x480 frames.

Negatives, two kinds:
- background: ROIs of a positive's size at the same image rows, placed at random where
  they overlap no labelled object (any class, DontCare regions included); where the data
  has lidar, one whose column holds at least `lidar_min_points` points standing
  `structure_min_height_m` to `structure_max_height_m` above the ground and no farther
  than `standing_tolerance_m` beyond its range is a background with something standing
  there (`standing_in_column`: a hedge, a wall, a post), not an empty scene;
- points (lidar structure, radar returns): clusters of sensor points 3-25 m away that lie
  at least `clearance_m` from every labelled box and outside DontCare regions, each one a
  column at the cluster's nearest point - the paper's kind of negative, a sensor target
  with no obstacle behind it. Lidar points must also stand `structure_min_height_m` to
  `structure_max_height_m` above the ground (a plane fitted to the scan), so that the
  negatives are walls, poles, trees and rails, not the road.

Frames: the sensor frame (lidar; x forward, y left, z up) is the "ground frame" of
common/calibration.py up to a shift in z; X_cam = R X_sensor + t.
"""

import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.services.fusion.roi import ColumnGeometry, ColumnProjector, Roi
from aeb_radar_camera.tools.eval.records import KIND_BACKGROUND, KIND_OBJECT
from aeb_radar_camera.tools.sim.world import nearest_point

Box2D = tuple[float, float, float, float]     # x0, y0, x1, y1 in pixels


@dataclass(frozen=True)
class Box3D:
    """A labelled object: its footprint (4, 2) in the sensor frame's x-y plane, the z of
    its bottom and its height; `bbox` its 2-D box in the original image."""

    obj_class: str
    footprint: np.ndarray
    z_bottom: float
    height: float
    bbox: Box2D


@dataclass(frozen=True)
class DatasetFrame:
    """One labelled frame of a data set, read by an adapter."""

    dataset: str
    split: str
    frame_id: str
    image_path: Path
    k: np.ndarray              # 3x3 intrinsics of the original image
    width: int
    height: int
    r: np.ndarray              # camera from sensor frame
    t: np.ndarray
    boxes: list[Box3D]
    dontcare: list[Box2D]
    lidar: np.ndarray | None = None     # (N, 3) sensor frame
    radar: np.ndarray | None = None     # (M, 3) sensor frame


@dataclass(frozen=True)
class PaperRoiSettings:
    focal_px: float = 449.0
    column_height_m: float = 2.2
    column_width_m: float = 1.08
    padding_px: int = 22
    min_range_m: float = 3.0
    max_range_m: float = 25.0
    classes: tuple[str, ...] = ("Car", "Pedestrian", "Person_sitting", "Cyclist")
    background_per_object: int = 2
    # Share of a background ROI's area allowed on labelled boxes (0: none at all).
    background_max_overlap: float = 0.0
    clearance_m: float = 1.0
    structure_min_height_m: float = 0.3
    structure_max_height_m: float = 2.0
    cluster_cell_m: float = 0.9
    lidar_min_points: int = 5
    # A background column's points up to this far beyond its range stand "at" it (the
    # lidar's own range error is centimetres; this is the obstacle's depth).
    standing_tolerance_m: float = 1.0
    radar_min_points: int = 1
    radar_cell_m: float = 0.5


@dataclass(frozen=True)
class Candidate:
    """A ROI to score: `truth` YES for an object, NO for a negative."""

    kind: str
    index: int
    roi: Roi
    column: Roi
    range_m: float
    obj_class: str
    truth: str
    # A negative whose column meets a labelled object's image box: an object stands in
    # front of (or behind) the sensor point, at another range.
    object_in_view: bool = False
    # The calibration the column was projected with (its ground frame stands on the
    # column's ground) and the column's foot in it: what a depth verifier needs.
    calibration: Calibration | None = None
    xy_m: tuple[float, float] | None = None


@dataclass
class Scaled:
    """The frame at the evaluation's pixel scale."""

    scale: float
    width: int
    height: int
    k: np.ndarray
    sx: float
    sy: float
    counters: dict[str, int] = field(default_factory=dict)

    def box(self, b: Box2D) -> Box2D:
        return ((b[0] + 0.5) * self.sx - 0.5, (b[1] + 0.5) * self.sy - 0.5,
                (b[2] + 0.5) * self.sx - 0.5, (b[3] + 0.5) * self.sy - 0.5)


def orthonormal(r: np.ndarray) -> np.ndarray:
    """The rotation nearest to `r` (calibration files print 7 digits)."""
    u, _, vt = np.linalg.svd(np.asarray(r, dtype=np.float64))
    out = u @ vt
    if np.linalg.det(out) < 0:
        raise ValueError("the camera-from-sensor matrix is a reflection")
    return out


def scaled(frame: DatasetFrame, focal_px: float) -> Scaled:
    """Resampling that brings the horizontal focal length to `focal_px` (intrinsics of
    the resized image with the same pixel-centre convention as cv2.resize)."""
    from aeb_radar_camera.tools.eval.frames import resized_size

    scale = focal_px / float(frame.k[0, 0])
    w, h = resized_size(frame.width, frame.height, scale)
    sx, sy = w / frame.width, h / frame.height
    k = np.array([[frame.k[0, 0] * sx, 0.0, (frame.k[0, 2] + 0.5) * sx - 0.5],
                  [0.0, frame.k[1, 1] * sy, (frame.k[1, 2] + 0.5) * sy - 0.5],
                  [0.0, 0.0, 1.0]])
    return Scaled(scale, w, h, k, sx, sy)


def camera_xy(frame: DatasetFrame) -> tuple[float, float]:
    """The camera's optical centre on the sensor frame's x-y plane: ranges count from it."""
    c = -frame.r.T @ frame.t
    return float(c[0]), float(c[1])


def projector(frame: DatasetFrame, sc: Scaled, z_ground: float,
              s: PaperRoiSettings) -> ColumnProjector:
    """Fusion's projector for a column standing at height `z_ground` of the sensor frame."""
    cal = Calibration.from_matrices(sc.width, sc.height, sc.k, np.zeros(5), frame.r,
                                    frame.t + frame.r[:, 2] * z_ground,
                                    name=f"{frame.dataset}-{frame.frame_id}")
    return ColumnProjector(cal, ColumnGeometry(s.column_height_m, s.column_width_m / 2.0,
                                               s.padding_px))


def footprint_distance(xy: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Distance of each point (N, 2) to a convex footprint (4, 2); 0 inside."""
    p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    best = np.full(len(p), np.inf)
    inside = np.ones(len(p), bool)
    sign = None
    for i in range(4):
        a, b = corners[i], corners[(i + 1) % 4]
        ab = b - a
        t = np.clip(((p - a) @ ab) / max(float(ab @ ab), 1e-12), 0.0, 1.0)
        q = a + t[:, None] * ab
        best = np.minimum(best, np.hypot(*(p - q).T))
        cross = ab[0] * (p[:, 1] - a[1]) - ab[1] * (p[:, 0] - a[0])
        side = cross >= 0
        sign = side if sign is None else sign
        inside &= side == sign
    best[inside] = 0.0
    return best


def object_candidates(frame: DatasetFrame, sc: Scaled, s: PaperRoiSettings
                      ) -> list[Candidate]:
    cx, cy = camera_xy(frame)
    out = []
    for i, box in enumerate(frame.boxes):
        if box.obj_class not in s.classes:
            continue
        nx, ny = nearest_point(box.footprint, cx, cy)
        rng_m = math.hypot(nx - cx, ny - cy)
        if not s.min_range_m <= rng_m <= s.max_range_m:
            continue
        proj = projector(frame, sc, box.z_bottom, s)
        got = proj.boxes(np.array([[nx, ny]]))[0]
        if got is None:
            sc.counters["object_not_visible"] = sc.counters.get("object_not_visible", 0) + 1
            continue
        out.append(Candidate(KIND_OBJECT, i, got[0], got[1], rng_m, box.obj_class, "YES",
                             calibration=proj.cal, xy_m=(float(nx), float(ny))))
    return out


def free_rois(roi: Roi, occupied: list[Box2D], width: int, n: int,
              rng: np.random.Generator, max_overlap: float = 0.0) -> list[Roi]:
    """Up to `n` ROIs of `roi`'s size at its rows, at random columns where at most
    `max_overlap` of their area lies on the boxes of `occupied` (which they join; they
    never overlap each other)."""
    _, y, w, h = roi
    span = width - w + 1
    if span <= 0:
        return []
    covered = np.zeros((h, width), bool)
    for bx0, by0, bx1, by1 in occupied:
        r0, r1 = max(0, math.floor(by0) - y), min(h, math.ceil(by1) + 1 - y)
        c0, c1 = max(0, math.floor(bx0)), min(width, math.ceil(bx1) + 1)
        if r0 < r1 and c0 < c1:
            covered[r0:r1, c0:c1] = True
    per_column = np.r_[0, np.cumsum(covered.sum(axis=0))]
    overlap = (per_column[w:] - per_column[:-w]) / float(w * h)
    allowed = overlap <= max_overlap + 1e-12
    out = []
    for _ in range(n):
        free = np.flatnonzero(allowed)
        if len(free) == 0:
            break
        x0 = int(free[rng.integers(len(free))])
        out.append(Roi(x0, y, w, h))
        allowed[max(0, x0 - w + 1):min(span, x0 + w)] = False
        occupied.append((x0, y, x0 + w - 1, y + h - 1))
    return out


def background_candidates(frame: DatasetFrame, sc: Scaled, positives: list[Candidate],
                          s: PaperRoiSettings, rng: np.random.Generator) -> list[Candidate]:
    """Up to `background_per_object` ROIs per positive: its size, its rows, on no
    labelled object and on no other background ROI."""
    occupied = [sc.box(b.bbox) for b in frame.boxes] + [sc.box(b) for b in frame.dontcare]
    out: list[Candidate] = []
    for pos in positives:
        got = free_rois(pos.roi, occupied, sc.width, s.background_per_object, rng,
                        s.background_max_overlap)
        if len(got) < s.background_per_object:
            sc.counters["background_no_room"] = sc.counters.get("background_no_room", 0) + 1
        # The positive's column, moved with its ROI: a radar target at its range and
        # rows with nothing labelled there.
        dx, dy = pos.column.x - pos.roi.x, pos.column.y - pos.roi.y
        out += [Candidate(KIND_BACKGROUND, len(out) + k, roi,
                          Roi(roi.x + dx, roi.y + dy, pos.column.w, pos.column.h),
                          pos.range_m, "", "NO", calibration=pos.calibration, xy_m=pos.xy_m)
                for k, roi in enumerate(got)]
    return out


def image_points(frame: DatasetFrame, sc: Scaled, points: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixel columns u, rows v (at the evaluation's scale) of sensor-frame points (N, 3),
    and whether each lies ahead of the camera (u, v of the others are meaningless)."""
    cam = points @ frame.r.T + frame.t
    ahead = cam[:, 2] > 0.1
    z = np.where(ahead, cam[:, 2], np.inf)
    u = (sc.k[0, 0] * cam[:, 0] + sc.k[0, 2] * cam[:, 2]) / z
    v = (sc.k[1, 1] * cam[:, 1] + sc.k[1, 2] * cam[:, 2]) / z
    return u, v, ahead


def standing_in_column(frame: DatasetFrame, sc: Scaled, candidates: list[Candidate],
                       points: np.ndarray, plane: tuple[float, float, float],
                       s: PaperRoiSettings) -> list[bool]:
    """Per candidate: do at least `lidar_min_points` of `points` (sensor frame) project
    into its column box's columns within its ROI's rows, stand `structure_min_height_m`
    to `structure_max_height_m` above the ground plane, and lie no farther from the
    camera than its range + `standing_tolerance_m`?"""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    cx, cy = camera_xy(frame)
    height = p[:, 2] - (plane[0] * p[:, 0] + plane[1] * p[:, 1] + plane[2])
    dist = np.hypot(p[:, 0] - cx, p[:, 1] - cy)
    u, v, ahead = image_points(frame, sc, p)
    standing = (ahead & (height >= s.structure_min_height_m)
                & (height <= s.structure_max_height_m))
    out = []
    for c in candidates:
        inside = (standing & (u >= c.column.x) & (u < c.column.x + c.column.w)
                  & (v >= c.roi.y) & (v < c.roi.y + c.roi.h)
                  & (dist <= c.range_m + s.standing_tolerance_m))
        out.append(int(np.count_nonzero(inside)) >= s.lidar_min_points)
    return out


def ground_plane(points: np.ndarray, rng: np.random.Generator, iterations: int = 80,
                 tolerance_m: float = 0.15) -> tuple[float, float, float] | None:
    """z = a x + b y + c of the ground under a scan (RANSAC over near, low points, then
    least squares on the inliers); None when no plane has enough support."""
    p = np.asarray(points, dtype=np.float64)
    near = p[(np.hypot(p[:, 0], p[:, 1]) < 30.0)]
    if len(near) < 50:
        return None
    low = near[near[:, 2] <= np.quantile(near[:, 2], 0.5)]
    best, best_n = None, 0
    for _ in range(iterations):
        a, b, c = low[rng.choice(len(low), 3, replace=False)]
        n = np.cross(b - a, c - a)
        if abs(n[2]) < 0.9 * np.linalg.norm(n) or n[2] == 0:
            continue                           # not a near-horizontal plane
        d = np.abs((near - a) @ n) / np.linalg.norm(n)
        count = int((d < tolerance_m).sum())
        if count > best_n:
            best, best_n = (a, n), count
    if best is None or best_n < 0.1 * len(near):
        return None
    a, n = best
    inliers = near[np.abs((near - a) @ n) / np.linalg.norm(n) < tolerance_m]
    design = np.c_[inliers[:, 0], inliers[:, 1], np.ones(len(inliers))]
    coef, *_ = np.linalg.lstsq(design, inliers[:, 2], rcond=None)
    return float(coef[0]), float(coef[1]), float(coef[2])


def point_candidates(frame: DatasetFrame, sc: Scaled, points: np.ndarray, kind: str,
                     plane: tuple[float, float, float] | None, s: PaperRoiSettings,
                     min_height_m: float | None, max_height_m: float | None,
                     cell_m: float, min_points: int) -> list[Candidate]:
    """One negative per cluster of points on no labelled object (module docstring)."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0 or plane is None:
        return []
    cx, cy = camera_xy(frame)
    ground_z = plane[0] * p[:, 0] + plane[1] * p[:, 1] + plane[2]
    height = p[:, 2] - ground_z
    rng_m = np.hypot(p[:, 0] - cx, p[:, 1] - cy)
    keep = (rng_m >= s.min_range_m) & (rng_m <= s.max_range_m)
    if min_height_m is not None:
        keep &= height >= min_height_m
    if max_height_m is not None:
        keep &= height <= max_height_m
    u, v, ahead = image_points(frame, sc, p)
    keep &= ahead & (u >= 0) & (u < sc.width) & (v >= 0) & (v < sc.height)
    for box in frame.boxes:
        keep &= footprint_distance(p[:, :2], box.footprint) >= s.clearance_m
    for b in frame.dontcare:
        x0, y0, x1, y1 = sc.box(b)
        keep &= ~((u >= x0) & (u <= x1) & (v >= y0) & (v <= y1))
    idx = np.flatnonzero(keep)
    if len(idx) == 0:
        return []
    # Clusters: connected cells of a bird's-eye grid.
    gx = np.floor(p[idx, 0] / cell_m).astype(np.int64)
    gy = np.floor(p[idx, 1] / cell_m).astype(np.int64)
    gx -= gx.min()
    gy -= gy.min()
    grid = np.zeros((int(gx.max()) + 1, int(gy.max()) + 1), np.uint8)
    grid[gx, gy] = 255
    _, labels = cv2.connectedComponents(grid, connectivity=8)
    cluster = labels[gx, gy]
    boxes2d = [sc.box(b.bbox) for b in frame.boxes]
    out: list[Candidate] = []
    for c in np.unique(cluster):
        members = idx[cluster == c]
        if len(members) < min_points:
            continue
        j = members[np.argmin(rng_m[members])]
        proj = projector(frame, sc, float(ground_z[j]), s)
        got = proj.boxes(p[j:j + 1, :2])[0]
        if got is None:
            continue
        cx0, cy0, cw, ch = got[1]
        in_view = any(not (cx0 + cw - 1 < bx0 or cx0 > bx1 or cy0 + ch - 1 < by0 or cy0 > by1)
                      for bx0, by0, bx1, by1 in boxes2d)
        out.append(Candidate(kind, len(out), got[0], got[1], float(rng_m[j]), "", "NO",
                             in_view, proj.cal, (float(p[j, 0]), float(p[j, 1]))))
    return out
