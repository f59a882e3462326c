"""Configuration of the camera service: the `[camera]` table and its `[camera.source]`.

The source is a tagged union on `kind`; each kind has its own fields, and an unknown
field or kind fails at start naming it. A source `fps` of 0 means "the camera's `fps`".
File paths (calibration, bag, video file, folder) are relative to the config file's
folder. See docs/camera.md.
"""

import re
from typing import Annotated, Any

import msgspec

from aeb_radar_camera.common.config.base import ServiceConfig
from aeb_radar_camera.common.config.paths import ConfigPath
from aeb_radar_camera.common.messages.camera import DEPTH_CODECS

Fps = Annotated[float, msgspec.Meta(ge=0, le=1000)]
_CAMERA_NAME = re.compile(r"^[A-Za-z0-9_.\-]+$")
_FACTORY = r"^[A-Za-z_][\w.]*:[A-Za-z_][\w.]*$"


class RealSenseSource(msgspec.Struct, frozen=True, forbid_unknown_fields=True, tag_field="kind",
                      tag="realsense"):
    """An Intel RealSense camera (colour stream) or a RealSense `.bag` recording.

    Needs the optional extra: `pip install 'aeb-radar-camera[realsense]'`.
    """

    serial: str = ""            # empty: the first device found
    bag: ConfigPath = ""        # a recording (.bag, or .db3 from librealsense 2.59) to play
    loop: bool = False          # bag only: play again from the start at its end
    width: Annotated[int, msgspec.Meta(gt=0)] = 848
    height: Annotated[int, msgspec.Meta(gt=0)] = 480
    fps: Annotated[int, msgspec.Meta(ge=0, le=90)] = 30   # 0: the camera's fps
    timeout_ms: Annotated[int, msgspec.Meta(ge=10)] = 1000  # no frame for this long: error
    depth: bool = True          # aligned depth with each frame (a bag without it: colour)


class OpenCVSource(msgspec.Struct, frozen=True, forbid_unknown_fields=True, tag_field="kind",
                   tag="opencv"):
    """Anything cv2.VideoCapture opens: a V4L2 device index ("0") or path
    ("/dev/video0"), a video file, or a stream URL.

    Files are paced at `fps` (0: the camera's fps) and may loop; devices deliver at their
    own rate (`width`, `height` and `fps` are requested from them when non-zero).
    """

    device: ConfigPath
    backend: str = "any"        # any | v4l2 | ffmpeg | gstreamer
    loop: bool = False          # files only
    fps: Fps = 0.0
    width: Annotated[int, msgspec.Meta(ge=0)] = 0
    height: Annotated[int, msgspec.Meta(ge=0)] = 0
    timeout_ms: Annotated[int, msgspec.Meta(ge=10)] = 1000  # device read timeout

    def __post_init__(self) -> None:
        if not self.device:
            raise ValueError("`device` must name a device index, device path, file or URL")
        if self.backend not in ("any", "v4l2", "ffmpeg", "gstreamer"):
            raise ValueError(f"backend {self.backend!r}: expected any, v4l2, ffmpeg or gstreamer")


class FolderSource(msgspec.Struct, frozen=True, forbid_unknown_fields=True, tag_field="kind",
                   tag="folder"):
    """Image files of a folder in natural sort order ("f2" before "f10"), paced at `fps`."""

    path: ConfigPath
    fps: Fps = 0.0
    loop: bool = True
    extensions: tuple[str, ...] = (".jpg", ".jpeg", ".png", ".bmp", ".ppm", ".pgm", ".tif",
                                   ".tiff", ".webp")

    def __post_init__(self) -> None:
        if not self.path:
            raise ValueError("`path` must name a folder of images")


class SyntheticSource(msgspec.Struct, frozen=True, forbid_unknown_fields=True, tag_field="kind",
                      tag="synthetic"):
    """A source plugin: `factory` ("package.module:callable") returns a FrameSource.

    `options` are passed to it unchanged (see services/camera/plugin.py). The default is
    the moving-box demo scene, a SIMULATION (tools/sim/moving_box.py).
    """

    factory: Annotated[str, msgspec.Meta(pattern=_FACTORY)] = (
        "aeb_radar_camera.tools.sim.moving_box:make_source")
    fps: Fps = 0.0
    options: dict[str, Any] = msgspec.field(default_factory=dict)


Source = RealSenseSource | OpenCVSource | FolderSource | SyntheticSource


class DepthSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The `[camera.depth]` table: how depth from a source that has it is published
    (CAMERA_DEPTH, beside each JPEG frame with the same capture stamp).

    `decimation` k publishes every k-th pixel of every k-th row (2: 424x240 from the
    D435's 848x480, a quarter of the bytes; benchmarks/bench_depth.py); `fps` at most this
    rate (0: with every published frame).
    """

    publish: bool = True
    decimation: Annotated[int, msgspec.Meta(ge=1, le=8)] = 2
    fps: Fps = 0.0
    codec: str = "zstd"

    def __post_init__(self) -> None:
        if self.codec not in DEPTH_CODECS:
            raise ValueError(f"depth codec {self.codec!r}: expected one of "
                             f"{', '.join(DEPTH_CODECS)}")


class CameraSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The `[camera]` table.

    `fps` is the publish rate: frames arriving faster are skipped (counted as decimated).
    `calibration` is required: the size, K, distortion and extrinsics that CameraInfo
    carries and that frames must match.
    """

    calibration: ConfigPath
    name: str = "front"
    fps: Annotated[float, msgspec.Meta(gt=0, le=1000)] = 30.0
    jpeg_quality: Annotated[int, msgspec.Meta(ge=1, le=100)] = 80
    source: Source = msgspec.field(default_factory=lambda: RealSenseSource())
    depth: DepthSettings = msgspec.field(default_factory=DepthSettings)
    stall_timeout_s: Annotated[float, msgspec.Meta(gt=0)] = 1.0
    info_period_s: Annotated[float, msgspec.Meta(gt=0)] = 1.0
    reopen_initial_s: Annotated[float, msgspec.Meta(gt=0)] = 0.5
    reopen_max_s: Annotated[float, msgspec.Meta(gt=0)] = 5.0
    exit_at_end: bool = False   # exit 0 when a finite source ends (else keep serving info)
    stats_period_s: Annotated[float, msgspec.Meta(ge=0)] = 10.0   # 0: no stats log lines

    def __post_init__(self) -> None:
        if not self.calibration:
            raise ValueError("`calibration` must name a calibration TOML")
        if not _CAMERA_NAME.match(self.name):
            raise ValueError(f"camera name {self.name!r} must be letters, digits, '_', '-', '.'")
        if self.reopen_max_s < self.reopen_initial_s:
            raise ValueError("`reopen_max_s` must be >= `reopen_initial_s`")


class CameraConfig(ServiceConfig, frozen=True, forbid_unknown_fields=True, kw_only=True):
    camera: CameraSettings
