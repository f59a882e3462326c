"""Any cv2.VideoCapture: a V4L2 device (index "0" or path "/dev/video0"), a video file,
or a stream URL.

Files are paced at a fixed rate (their own frame rate unless configured) and may loop;
a file's last frame ends the stream. Devices deliver at their own rate; a device read
that fails or times out raises SourceError so that the camera reopens it. Frames are
stamped with the wall clock when read() returns: driver buffering is not removed, which
is why the capture buffer is set to one frame where the backend allows it.
"""

import time
from collections.abc import Callable
from pathlib import Path

import cv2

from aeb_radar_camera.common.clock import wall_ns
from aeb_radar_camera.services.camera.source import (
    EndOfStream,
    Frame,
    FrameSource,
    Pacer,
    SourceError,
    as_bgr,
)

BACKENDS = {"any": cv2.CAP_ANY, "v4l2": cv2.CAP_V4L2, "ffmpeg": cv2.CAP_FFMPEG,
            "gstreamer": cv2.CAP_GSTREAMER}


class OpenCVSource(FrameSource):
    kind = "opencv"

    def __init__(self, device: str, fps: float = 0.0, fallback_fps: float = 30.0,
                 loop: bool = False, backend: str = "any", width: int = 0, height: int = 0,
                 timeout_ms: int = 1000,
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep,
                 wall_clock: Callable[[], int] = wall_ns) -> None:
        """`fps` 0: a file plays at its own rate (or `fallback_fps` when it has none);
        a device runs at its default. Raises ValueError for an unknown backend."""
        super().__init__()
        if backend not in BACKENDS:
            raise ValueError(f"unknown OpenCV backend {backend!r}; expected {sorted(BACKENDS)}")
        self.device = device
        self.is_file = Path(device).is_file()
        self.fps = fps
        self.fallback_fps = fallback_fps
        self.loop = loop
        self.backend = backend
        self.width = width
        self.height = height
        self.timeout_ms = timeout_ms
        self._clock = clock
        self._sleep = sleep
        self._wall = wall_clock
        self._cap: cv2.VideoCapture | None = None
        self._pacer: Pacer | None = None

    def describe(self) -> str:
        what = "file" if self.is_file else "device"
        rate = f" at {1 / self._pacer.period_s:g} fps" if self._pacer else ""
        return f"opencv {what} {self.device}{rate} (backend {self.backend})"

    def open(self) -> None:
        target: int | str = int(self.device) if self.device.isdigit() else self.device
        params = [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, self.timeout_ms * 5,
                  cv2.CAP_PROP_READ_TIMEOUT_MSEC, self.timeout_ms]
        cap = cv2.VideoCapture(target, BACKENDS[self.backend], params)
        if not cap.isOpened():
            cap.release()
            raise SourceError(f"OpenCV cannot open {self.device!r} (backend {self.backend})")
        if not self.is_file:
            for prop, value in ((cv2.CAP_PROP_FRAME_WIDTH, self.width),
                                (cv2.CAP_PROP_FRAME_HEIGHT, self.height),
                                (cv2.CAP_PROP_FPS, self.fps)):
                if value:
                    cap.set(prop, value)
            cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)
            self._pacer = None
        else:
            rate = self.fps or cap.get(cv2.CAP_PROP_FPS) or self.fallback_fps
            self._pacer = Pacer(rate if 0 < rate <= 1000 else self.fallback_fps,
                                self._clock, self._sleep)
        self._cap = cap

    def read(self) -> Frame:
        cap = self._cap
        if cap is None:
            raise SourceError("read before open")
        ok, image = cap.read()
        if not ok and self.is_file and self.loop:
            cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
            ok, image = cap.read()
            if not ok:
                raise SourceError(f"cannot rewind {self.device!r}")
        if not ok or image is None:
            if self.is_file:
                raise EndOfStream(f"end of video file {self.device}")
            raise SourceError(f"no frame from {self.device!r} within {self.timeout_ms} ms")
        try:
            image = as_bgr(image)
        except ValueError as exc:
            raise SourceError(f"{self.device!r}: {exc}") from exc
        if self._pacer is not None:
            self._pacer.wait()
        return Frame(image=image, stamp_ns=self._wall())

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None
