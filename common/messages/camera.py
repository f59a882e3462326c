"""Messages published by the camera service."""

import msgspec

from aeb_radar_camera.common.messages.header import Header

# DepthFrame.codec values (common/depth_image.py implements them).
DEPTH_CODECS = ("zstd", "png")


class CompressedFrame(msgspec.Struct, frozen=True, gc=False, kw_only=True):
    """One JPEG frame. `header.stamp_ns` is the capture time (wall clock).

    `crc32` is zlib.crc32 of `jpeg`, set by the camera: a JPEG with a flipped bit often
    still decodes, into wrong pixels, so every decoder checks it first
    (common.imaging). None (a publisher that does not set it): not checked."""

    header: Header
    camera: str
    width: int
    height: int
    jpeg: bytes
    crc32: int | None = None


class DepthFrame(msgspec.Struct, frozen=True, gc=False, kw_only=True):
    """One depth image aligned to a colour frame (common/depth_image.py encodes it).

    `header.stamp_ns` is the capture time of the colour frame it is aligned to (the same
    stamp as that `CompressedFrame`: fusion pairs them by it). Pixel (u, v) of the depth
    image covers pixels (u, v) * (colour size / depth size) of the colour frame (the
    depth may be published at a lower resolution). `data` is uint16 depth in `units_m`
    (0: no return) coded with `codec` ("zstd" or "png", both lossless).
    """

    header: Header
    camera: str
    width: int
    height: int
    codec: str
    data: bytes
    units_m: float = 0.001


class CameraInfo(msgspec.Struct, frozen=True, gc=False, kw_only=True):
    """Size, intrinsics and radar-to-camera extrinsics.

    `k` is the 3x3 camera matrix row-major, `dist` OpenCV distortion coefficients
    (k1, k2, p1, p2[, k3...]), `r` (3x3 row-major) and `t_m` map a point from the radar
    frame to the camera frame: X_cam = R X_radar + t.

    `frames_dropped` counts frames replaced before the encoder took them (congestion: the
    camera drops rather than queues); `read_errors` counts unreadable inputs skipped,
    frames rejected (wrong size) and source failures.
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
    # Added by the camera service (defaults keep older payloads decodable):
    frames_captured: int = 0   # delivered by the source
    frames_decimated: int = 0  # skipped because the source is faster than `fps`
    reopens: int = 0           # times the source failed while streaming and was reopened
    errors: dict[str, int] = msgspec.field(default_factory=dict)  # read_errors by reason
    depth_published: int = 0   # DepthFrames published (0: the source has no depth)
