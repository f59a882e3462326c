"""Messages published by the camera service."""

import msgspec

from common.messages.header import Header


class CompressedFrame(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """One JPEG frame. `header.stamp_ns` is the capture time (wall clock)."""

    header: Header
    camera: str
    width: int
    height: int
    jpeg: bytes


class CameraInfo(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Size, intrinsics and radar-to-camera extrinsics.

    `k` is the 3x3 camera matrix row-major, `dist` OpenCV distortion coefficients
    (k1, k2, p1, p2[, k3...]), `r` (3x3 row-major) and `t_m` map a point from the radar
    frame to the camera frame: X_cam = R X_radar + t.
    """

    header: Header
    camera: str
    width: int
    height: int
    k: tuple[float, ...]
    dist: tuple[float, ...]
    r: tuple[float, ...]
    t_m: tuple[float, ...]
    fps: float
    source: str                # e.g. "folder", "opencv", "realsense", "synthetic"
    frames_published: int
    frames_dropped: int
    read_errors: int
    healthy: bool
    status: str                # empty when healthy, else why not
