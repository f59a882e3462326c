"""Intel RealSense colour stream (D435: 848x480 at 30 fps) or a RealSense `.bag` recording,
through pyrealsense2 (the optional extra `realsense`, imported only when this source opens).

Depth (`depth = true`, the default): the depth stream at the colour's size and rate,
aligned to the colour frame by librealsense's `align` (each depth pixel re-projected into
the colour camera), delivered with the frame as uint16 millimetres (0: no return); a
device whose depth unit is not 1 mm is converted. A recording without a depth stream
plays colour only.

Stamps: a device frame whose timestamp domain is global or system time (the D400 default
is global time: the device clock mapped onto the host clock) is stamped with that
capture time; a hardware-clock stamp, a stamp more than a second away from the host
clock, and every frame of a recording are stamped with the wall clock at arrival.
"""

import contextlib
import importlib
from collections.abc import Callable
from types import ModuleType
from typing import Any

import cv2
import numpy as np

from aeb_radar_camera.common.clock import wall_ns
from aeb_radar_camera.services.camera.source import (
    EndOfStream,
    Frame,
    FrameSource,
    SourceConfigError,
    SourceError,
)

_MAX_CLOCK_GAP_NS = 1_000_000_000
_MM = 0.001
INSTALL_HINT = "pip install 'aeb-radar-camera[realsense]' (or pip install pyrealsense2)"


def import_pyrealsense2() -> ModuleType:
    """The pyrealsense2 module. Raises SourceConfigError with the install command."""
    try:
        return importlib.import_module("pyrealsense2")
    except ImportError as exc:
        raise SourceConfigError(
            f"the realsense source needs pyrealsense2, which is not installed: {INSTALL_HINT}"
        ) from exc


class RealSenseSource(FrameSource):
    kind = "realsense"

    def __init__(self, serial: str = "", bag: str = "", loop: bool = False, width: int = 848,
                 height: int = 480, fps: int = 30, timeout_ms: int = 1000, depth: bool = True,
                 loader: Callable[[], ModuleType] = import_pyrealsense2,
                 wall_clock: Callable[[], int] = wall_ns) -> None:
        super().__init__()
        self.serial = serial
        self.bag = bag
        self.loop = loop
        self.width = width
        self.height = height
        self.fps = fps
        self.timeout_ms = timeout_ms
        self.depth = depth
        self._loader = loader
        self._wall = wall_clock
        self._rs: Any = None
        self._pipeline: Any = None
        self._playback: Any = None
        self._align: Any = None
        self._depth_scale = _MM

    def describe(self) -> str:
        what = f"recording {self.bag}" if self.bag else f"device {self.serial or '(first found)'}"
        depth = " with aligned depth" if self.depth else ""
        return f"realsense {what} colour {self.width}x{self.height} at {self.fps} fps{depth}"

    def _config(self, rs: Any, depth: bool) -> Any:
        config = rs.config()
        if self.bag:
            # A recording's own format is used (converted to BGR below); a size or rate the
            # recording does not hold would make start() fail.
            config.enable_device_from_file(self.bag, repeat_playback=self.loop)
            config.enable_stream(rs.stream.color)
            if depth:
                config.enable_stream(rs.stream.depth)
        else:
            if self.serial:
                config.enable_device(self.serial)
            config.enable_stream(rs.stream.color, self.width, self.height, rs.format.bgr8,
                                 self.fps)
            if depth:
                config.enable_stream(rs.stream.depth, self.width, self.height, rs.format.z16,
                                     self.fps)
        return config

    def open(self) -> None:
        rs = self._rs = self._loader()
        pipeline = rs.pipeline()
        if not self.bag:
            self._require_device(rs)
        depth = self.depth
        try:
            try:
                profile = pipeline.start(self._config(rs, depth))
            except RuntimeError:
                if not (self.bag and depth):
                    raise
                depth = False            # a colour-only recording
                profile = pipeline.start(self._config(rs, depth))
        except RuntimeError as exc:
            raise SourceError(f"cannot start RealSense {self.describe()}: {exc}") from exc
        self._pipeline = pipeline
        self._align = rs.align(rs.stream.color) if depth else None
        if depth:
            self._depth_scale = float(profile.get_device().first_depth_sensor()
                                      .get_depth_scale())
        if self.bag:
            self._playback = profile.get_device().as_playback()
            self._playback.set_real_time(True)

    def _require_device(self, rs: Any) -> None:
        """Raise SourceError at once when no (or not the configured) device is connected.

        pyrealsense2's pipeline.start() waits 15 s for a missing device while holding the
        GIL: the whole process, its signal handlers included, would freeze. Listing the
        devices takes milliseconds.
        """
        serials = [d.get_info(rs.camera_info.serial_number)
                   for d in rs.context().query_devices()]
        if not serials:
            raise SourceError("no RealSense device connected")
        if self.serial and self.serial not in serials:
            raise SourceError(
                f"RealSense {self.serial} not connected (connected: {', '.join(serials)})"
            )

    def read(self) -> Frame:
        rs, pipeline = self._rs, self._pipeline
        if pipeline is None:
            raise SourceError("read before open")
        try:
            frames = pipeline.wait_for_frames(self.timeout_ms)
        except RuntimeError as exc:
            if self._playback is not None and \
                    self._playback.current_status() == rs.playback_status.stopped:
                raise EndOfStream(f"end of recording {self.bag}") from exc
            raise SourceError(f"no frame within {self.timeout_ms} ms: {exc}") from exc
        arrival_ns = self._wall()
        if self._align is not None:
            frames = self._align.process(frames)
        color = frames.get_color_frame()
        if not color:
            raise SourceError("frameset without a colour frame")
        image = to_bgr(rs, color)
        depth = None
        if self._align is not None:
            got = frames.get_depth_frame()
            depth = to_millimetres(got, self._depth_scale) if got else None
        return Frame(image=image, stamp_ns=self._stamp(rs, color, arrival_ns), depth=depth)

    def _stamp(self, rs: Any, color: Any, arrival_ns: int) -> int:
        if self._playback is not None:
            return arrival_ns
        domain = color.get_frame_timestamp_domain()
        if domain in (rs.timestamp_domain.global_time, rs.timestamp_domain.system_time):
            stamp_ns = round(color.get_timestamp() * 1e6)
            if abs(arrival_ns - stamp_ns) <= _MAX_CLOCK_GAP_NS:
                return stamp_ns
        return arrival_ns

    def close(self) -> None:
        pipeline, self._pipeline, self._playback = self._pipeline, None, None
        self._align = None
        if pipeline is not None:
            # Already stopped (device unplugged): nothing left to release.
            with contextlib.suppress(RuntimeError):
                pipeline.stop()


def to_bgr(rs: Any, color: Any) -> np.ndarray:
    """A copy of the frame's pixels as BGR (librealsense recycles its buffers).

    Raises SourceError for a format this camera does not handle.
    """
    data = np.asanyarray(color.get_data())
    fmt = color.get_profile().format()
    if fmt == rs.format.bgr8:
        return np.array(data, dtype=np.uint8, copy=True)
    if fmt == rs.format.rgb8:
        return cv2.cvtColor(data, cv2.COLOR_RGB2BGR)
    if fmt == rs.format.bgra8:
        return np.ascontiguousarray(data[:, :, :3])
    if fmt == rs.format.rgba8:
        return cv2.cvtColor(data, cv2.COLOR_RGBA2BGR)
    if fmt == rs.format.yuyv:
        return cv2.cvtColor(data, cv2.COLOR_YUV2BGR_YUY2)
    raise SourceError(f"unsupported RealSense colour format {fmt}")


def to_millimetres(depth: Any, scale_m: float) -> np.ndarray:
    """A copy of an aligned depth frame as uint16 millimetres (0: no return)."""
    data = np.asanyarray(depth.get_data())
    if abs(scale_m - _MM) < 1e-9:
        return np.array(data, dtype=np.uint16, copy=True)
    mm = np.rint(data.astype(np.float64) * (scale_m / _MM))
    mm[mm > 65535] = 0
    return mm.astype(np.uint16)
