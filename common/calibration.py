"""Camera intrinsics and radar-to-camera extrinsics: one TOML format, validated at load,
and the projection every tool uses.

Frames:
- radar ground frame: origin on the ground directly below the radar, x forward, y left,
  z up (metres). A radar track (x, y) lives here; the paper's column is z in [0, 2.2].
- camera optical frame (OpenCV): x right, y down, z forward.

X_cam = R X_ground + t. The TOML gives either `r` and `t_m` directly, or the camera's
position in the ground frame and its yaw/pitch/roll (then R and t are derived).
See docs/calibration.md for the format and deploy/calibration/ for an example.
"""

import math
from pathlib import Path
from typing import Annotated

import cv2
import msgspec
import numpy as np

from aeb_radar_camera.common.config.loader import load_config, parse_config

# Ground frame axes (x fwd, y left, z up) expressed in the optical frame (x right, y down, z fwd).
GROUND_TO_OPTICAL = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])

_DIST_LENGTHS = (0, 4, 5, 8, 12, 14)
_ORTHO_TOL = 1e-4
# A field of view outside these bounds is a unit mistake (focal length in mm, not pixels)
# or a lens the pinhole model cannot describe.
FOV_MIN_DEG = 0.5
FOV_MAX_DEG = 170.0
# Plausibility bounds behind Calibration.warnings() (not errors: unusual rigs exist).
WARN_AXIS_DEG = 60.0
WARN_OFFSET_M = 5.0
WARN_PITCH_DEG = 30.0

Positive = Annotated[float, msgspec.Meta(gt=0)]


class Intrinsics(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    width: Annotated[int, msgspec.Meta(gt=0)]
    height: Annotated[int, msgspec.Meta(gt=0)]
    fx: Positive
    fy: Positive
    cx: float
    cy: float
    distortion: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        _require_finite("camera", (self.fx, self.fy, self.cx, self.cy, *self.distortion))
        if not 0 <= self.cx < self.width or not 0 <= self.cy < self.height:
            raise ValueError(
                f"principal point ({self.cx}, {self.cy}) outside the {self.width}x{self.height}"
                " image"
            )
        if len(self.distortion) not in _DIST_LENGTHS:
            raise ValueError(
                f"distortion has {len(self.distortion)} coefficients; OpenCV takes "
                f"{', '.join(map(str, _DIST_LENGTHS))}"
            )
        for axis, f, size in (("horizontal", self.fx, self.width),
                              ("vertical", self.fy, self.height)):
            fov = math.degrees(2 * math.atan(size / (2 * f)))
            if not FOV_MIN_DEG <= fov <= FOV_MAX_DEG:
                raise ValueError(
                    f"{axis} field of view {fov:.3g} deg (size {size} px, focal {f} px) is "
                    f"outside {FOV_MIN_DEG}-{FOV_MAX_DEG} deg: focal lengths are in pixels"
                )


class Pose(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The camera's position in the radar ground frame and its orientation.

    yaw: left positive, about z; pitch: nose down positive; roll: right side down positive.
    """

    position_m: tuple[float, float, float]
    yaw_deg: Annotated[float, msgspec.Meta(ge=-180, le=180)] = 0.0
    pitch_deg: Annotated[float, msgspec.Meta(gt=-90, lt=90)] = 0.0
    roll_deg: Annotated[float, msgspec.Meta(ge=-180, le=180)] = 0.0

    def __post_init__(self) -> None:
        _require_finite("pose", self.position_m)


class Extrinsics(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Exactly one of: `pose`, or `r` (3x3, rows) with `t_m`."""

    r: tuple[tuple[float, float, float], tuple[float, float, float],
             tuple[float, float, float]] | None = None
    t_m: tuple[float, float, float] | None = None
    pose: Pose | None = None

    def __post_init__(self) -> None:
        if (self.pose is None) == (self.r is None):
            raise ValueError("give either `pose` or `r` with `t_m`, not both and not neither")
        if self.r is not None and self.t_m is None:
            raise ValueError("`r` needs `t_m`")
        if self.t_m is not None:
            _require_finite("t_m", self.t_m)
        if self.r is not None:
            r = np.array(self.r, dtype=float)
            _require_finite("r", r.ravel())
            err = float(np.abs(r @ r.T - np.eye(3)).max())
            if err > _ORTHO_TOL:
                raise ValueError(f"`r` is not orthonormal (|R R^T - I| = {err:.2g})")
            if np.linalg.det(r) < 0:
                raise ValueError("`r` is a reflection (det < 0), not a rotation")


def _require_finite(what: str, values: "tuple[float, ...] | np.ndarray") -> None:
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"`{what}` has a value that is not a finite number")


class CalibrationFile(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    camera: Intrinsics
    extrinsics: Extrinsics
    name: str = ""


def pose_to_rt(pose: Pose) -> tuple[np.ndarray, np.ndarray]:
    """R, t (X_cam = R X_ground + t) for a camera at `pose`."""
    yaw, pitch, roll = (math.radians(a) for a in (pose.yaw_deg, pose.pitch_deg, pose.roll_deg))
    cz, sz = math.cos(yaw), math.sin(yaw)
    cy, sy = math.cos(pitch), math.sin(pitch)
    cx, sx = math.cos(roll), math.sin(roll)
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])  # +pitch turns the x axis down
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    body_to_ground = rz @ ry @ rx
    r = GROUND_TO_OPTICAL @ body_to_ground.T
    t = -r @ np.array(pose.position_m, dtype=float)
    return r, t


class Calibration:
    """A validated calibration with the matrices the projection needs."""

    def __init__(self, spec: CalibrationFile, origin: str = "") -> None:
        self.spec = spec
        self.origin = origin
        cam = spec.camera
        self.width = cam.width
        self.height = cam.height
        self.k = np.array([[cam.fx, 0.0, cam.cx], [0.0, cam.fy, cam.cy], [0.0, 0.0, 1.0]])
        self.dist = np.array(cam.distortion, dtype=float)
        ext = spec.extrinsics
        if ext.pose is not None:
            self.r, self.t = pose_to_rt(ext.pose)
        else:
            assert ext.r is not None and ext.t_m is not None
            self.r = np.array(ext.r, dtype=float)
            self.t = np.array(ext.t_m, dtype=float)
        self._zero = np.zeros(3)

    @classmethod
    def load(cls, path: str | Path) -> "Calibration":
        """Load and validate a calibration TOML. Raises ConfigError naming the field."""
        p = Path(path)
        return cls(load_config(p, CalibrationFile, what="calibration"), str(p))

    @classmethod
    def from_matrices(cls, width: int, height: int, k: np.ndarray, dist: np.ndarray,
                      r: np.ndarray, t: np.ndarray, name: str = "") -> "Calibration":
        """Build (and validate) from arrays, e.g. a received CameraInfo. Raises ConfigError."""
        data = {
            "name": name,
            "camera": {"width": width, "height": height, "fx": float(k[0, 0]),
                       "fy": float(k[1, 1]), "cx": float(k[0, 2]), "cy": float(k[1, 2]),
                       "distortion": [float(v) for v in np.ravel(dist)]},
            "extrinsics": {"r": np.asarray(r, dtype=float).reshape(3, 3).tolist(),
                           "t_m": [float(v) for v in np.ravel(t)]},
        }
        return cls(parse_config(data, CalibrationFile, name or "<matrices>"), name)

    @property
    def camera_position_m(self) -> np.ndarray:
        """The camera's optical centre in the radar ground frame: -R^T t."""
        return -self.r.T @ self.t

    def warnings(self) -> list[str]:
        """Plausibility checks for a forward AEB rig, as sentences (empty: nothing odd).

        Not errors, because unusual rigs exist; the camera logs them at start and
        `aeb calib-check` prints them. Each one usually means a sign or frame mistake.
        """
        out = []
        forward_depth = float(self.r[2, 0])   # optical z of the radar's forward axis
        angle = math.degrees(math.acos(max(-1.0, min(1.0, forward_depth))))
        if angle > WARN_AXIS_DEG:
            out.append(
                f"the optical axis is {angle:.0f} deg away from the radar's forward axis: "
                "is R inverted or given camera-to-radar? (X_cam = R X_radar + t)")
        offset = float(np.linalg.norm(self.camera_position_m))
        if offset > WARN_OFFSET_M:
            out.append(f"the camera is {offset:.1f} m from the radar's ground origin: "
                       "is t given in the wrong frame or unit? (metres; t = -R C)")
        optical_z_in_ground = self.r[2]        # the optical axis in ground coordinates
        pitch = math.degrees(math.asin(max(-1.0, min(1.0, -float(optical_z_in_ground[2])))))
        if abs(pitch) > WARN_PITCH_DEG:
            out.append(f"the camera is pitched {pitch:.0f} deg (positive: down)")
        position = self.camera_position_m
        if position[2] < 0:
            out.append(f"the camera is {-position[2]:.2f} m below the ground (z is up)")
        return out

    def to_camera(self, points_ground: np.ndarray) -> np.ndarray:
        """(N, 3) ground-frame points to (N, 3) camera-frame points."""
        return points_ground @ self.r.T + self.t

    def project(self, points_ground: np.ndarray, min_depth_m: float = 0.1
                ) -> tuple[np.ndarray, np.ndarray]:
        """Project (N, 3) ground-frame points with K, distortion, R and t.

        Returns (uv (N, 2) float pixels, in_front (N,) bool). Points with depth below
        `min_depth_m` are behind the camera: their uv is NaN, never a mirrored pixel.
        """
        pts = np.asarray(points_ground, dtype=float).reshape(-1, 3)
        cam = self.to_camera(pts)
        in_front = cam[:, 2] >= min_depth_m
        uv = np.full((len(pts), 2), np.nan)
        if in_front.any():
            proj, _ = cv2.projectPoints(cam[in_front].reshape(-1, 1, 3), self._zero,
                                        self._zero, self.k, self.dist)
            uv[in_front] = proj.reshape(-1, 2)
        return uv, in_front
