"""The interface every frame source implements, and the pacing clock shared by the
sources that have no clock of their own (image folders, video files, synthetic scenes).

Contract of a FrameSource (also in docs/camera.md):

- The camera calls `open()`, then `read()` repeatedly, then `close()`, all from ONE
  capture thread, never concurrently. After `close()` it may call `open()` again to
  reopen the source (after an error); a source must support that.
- `read()` blocks until the next frame and returns a `Frame`: `image` is BGR, `uint8`,
  shape (H, W, 3) (any strides; the camera copies nothing and may keep it until encoded,
  so a source must not reuse the array's memory afterwards), and `stamp_ns` is the
  wall-clock time (`time.time_ns()` domain) when the frame was captured. A paced source
  sleeps inside `read()` to keep its rate. A source with depth (RGB-D cameras, the
  simulator) also sets `depth`: uint16 millimetres (0: no return) aligned to `image`,
  of its height and width (the camera publishes it as DepthFrame beside the JPEG).
- `read()` must return or raise within about a second (or its own configured timeout):
  a device that delivers nothing raises `SourceError` rather than blocking forever.
- Errors: `SourceError` means "this source failed, close and reopen it later" (the camera
  reports it in CameraInfo and reopens with backoff). `EndOfStream` means a finite source
  is exhausted (the camera stops reading and reports "end of stream"). `SourceConfigError`
  means it can never work as configured (missing optional package, bad plugin): the
  camera exits with code 2. Any other exception is treated like `SourceError`.
- Inputs a source skips (an unreadable file) are counted in `skipped` and never raise.
"""

import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


class SourceError(RuntimeError):
    """The source failed (device gone, no frame in time); close it and reopen later."""


class EndOfStream(Exception):
    """A finite source (folder without loop, video file, recording) has no more frames."""


class SourceConfigError(ValueError):
    """The source can never work as configured (missing extra, bad plugin path)."""


@dataclass(frozen=True)
class Frame:
    """One captured image: BGR uint8 (H, W, 3), its wall-clock capture time in ns, and
    the depth aligned to it (uint16 mm (H, W), 0 = no return) when the source has depth."""

    image: np.ndarray
    stamp_ns: int
    depth: np.ndarray | None = None


class FrameSource(ABC):
    """A camera, a recording or a simulator delivering frames; see the module docstring."""

    #: short name reported in CameraInfo.source ("folder", "opencv", "realsense", ...)
    kind: str = "source"

    def __init__(self) -> None:
        self._skipped = 0

    @property
    def skipped(self) -> int:
        """Inputs skipped because they could not be read (cumulative over reopens)."""
        return self._skipped

    def describe(self) -> str:
        """One line naming what is read (for logs)."""
        return self.kind

    def open(self) -> None:  # noqa: B027 (most sources need no set-up)
        """Acquire the device or files. Raises SourceError, SourceConfigError."""

    @abstractmethod
    def read(self) -> Frame:
        """The next frame. Raises EndOfStream, SourceError."""

    def close(self) -> None:  # noqa: B027
        """Release the device; must not raise, and may be called when already closed."""


class Pacer:
    """Releases callers at a fixed rate: slot k at t0 + k * period.

    A caller that falls more than one period behind is re-synchronised (no burst of
    catch-up frames). `clock` and `sleep` are injectable so that tests need no real time.
    """

    def __init__(self, fps: float, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        if fps <= 0:
            raise ValueError(f"pacing rate must be positive, got {fps}")
        self.period_s = 1.0 / fps
        self._clock = clock
        self._sleep = sleep
        self._next: float | None = None

    def reset(self) -> None:
        self._next = None

    def wait(self) -> None:
        """Block until the next slot."""
        now = self._clock()
        if self._next is None:
            self._next = now
        elif self._next > now:
            self._sleep(self._next - now)
        elif now - self._next > self.period_s:
            self._next = now
        self._next += self.period_s


def as_bgr(image: np.ndarray) -> np.ndarray:
    """Grey (H, W) or (H, W, 1) and BGRA (H, W, 4) images to BGR; BGR passes unchanged.

    Raises ValueError for anything else (not uint8, other channel counts).
    """
    if image.dtype != np.uint8:
        raise ValueError(f"expected a uint8 image, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 3:
        return image
    if image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 1):
        grey = image.reshape(image.shape[0], image.shape[1])
        return np.repeat(grey[:, :, None], 3, axis=2)
    if image.ndim == 3 and image.shape[2] == 4:
        return np.ascontiguousarray(image[:, :, :3])
    raise ValueError(f"expected a BGR, BGRA or grey image, got shape {image.shape}")
