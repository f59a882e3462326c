"""Synthetic sources: the plugin interface the scenario simulator implements, and a
built-in scene (a textured box moving over a road under a sky) for tests and demos.

THIS IS A SIMULATION. The real sources are in folder.py, opencv_capture.py and
realsense.py, behind the same FrameSource interface.

Plugin interface
----------------
Config::

    [camera.source]
    kind = "synthetic"
    factory = "tools.sim.camera:make_source"   # "package.module:callable"
    fps = 30                                   # 0: the camera's fps
    options = { scenario = "cut_in" }          # passed through unchanged

The camera imports the module and calls ``factory(context)`` once, at start, with a
`SyntheticContext` (size and calibration of the camera, the pacing rate, the options, and
the camera's Bus when it runs inside the camera service). The factory returns a
`FrameSource` (services/camera/source.py), which the camera then drives like any other:
``open()``, ``read()`` repeatedly, ``close()``, all from one capture thread. ``read()``
returns a `Frame` (BGR uint8 (height, width, 3), wall-clock capture stamp in ns) and
paces itself (e.g. with `Pacer`); it raises `EndOfStream` when the scenario is over and
`SourceError` to simulate a camera failure. Frames must have the calibration's size.
The factory may raise `SourceConfigError` (or ValueError/TypeError) for bad options:
the camera exits with code 2 and the message.
"""

import importlib
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from common.calibration import Calibration
from common.clock import wall_ns
from services.camera.source import (
    EndOfStream,
    Frame,
    FrameSource,
    Pacer,
    SourceConfigError,
)

if TYPE_CHECKING:
    from common.bus import Bus


@dataclass(frozen=True)
class SyntheticContext:
    """What a synthetic source factory receives."""

    width: int
    height: int
    fps: float                       # the rate the source should deliver at
    calibration: Calibration | None  # the camera's calibration (None only in unit tests)
    camera: str = "front"
    options: dict[str, Any] = field(default_factory=dict)
    bus: "Bus | None" = None         # the camera's bus, to follow a simulated world


SourceFactory = Callable[[SyntheticContext], FrameSource]


def load_factory(path: str) -> SourceFactory:
    """The callable named by "package.module:attr". Raises SourceConfigError saying
    what is wrong (format, module not found, attribute missing, not callable)."""
    module_name, sep, attr = path.partition(":")
    if not sep or not module_name or not attr:
        raise SourceConfigError(f"synthetic factory {path!r}: expected 'package.module:callable'")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise SourceConfigError(
            f"synthetic factory {path!r}: cannot import module {module_name!r}: {exc}") from exc
    obj: Any = module
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise SourceConfigError(
                f"synthetic factory {path!r}: module {module_name!r} has no attribute {attr!r}")
        obj = getattr(obj, part)
    if not callable(obj):
        raise SourceConfigError(f"synthetic factory {path!r}: {attr!r} is not callable")
    factory: SourceFactory = obj
    return factory


def make_synthetic_source(path: str, context: SyntheticContext) -> FrameSource:
    """Load the factory and build the source. Raises SourceConfigError."""
    factory = load_factory(path)
    try:
        source = factory(context)
    except SourceConfigError:
        raise
    except (ValueError, TypeError, KeyError) as exc:
        raise SourceConfigError(f"synthetic factory {path!r} rejected its options: {exc}") from exc
    if not isinstance(source, FrameSource):
        raise SourceConfigError(
            f"synthetic factory {path!r} returned {type(source).__name__}, not a FrameSource")
    return source


class MovingBoxSource(FrameSource):
    """A checkered box sliding left-right over a road under a sky. A SIMULATION.

    Deterministic: frame n is the same image on every run. `frames` > 0 makes the source
    finite (EndOfStream after that many frames).
    """

    kind = "synthetic"

    def __init__(self, width: int, height: int, fps: float, frames: int = 0,
                 box_size_px: int = 96, speed_px_s: float = 120.0,
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep,
                 wall_clock: Callable[[], int] = wall_ns) -> None:
        super().__init__()
        if frames < 0 or box_size_px <= 0 or box_size_px >= min(width, height):
            raise ValueError(f"frames must be >= 0 and box_size_px in (0, {min(width, height)})")
        self.width = width
        self.height = height
        self.fps = fps
        self.frames = frames
        self.box = box_size_px
        self.speed_px_s = speed_px_s
        self._pacer = Pacer(fps, clock, sleep)
        self._wall = wall_clock
        self._n = 0
        self._background = road_scene(width, height)
        self._texture = checkerboard(box_size_px, max(4, box_size_px // 8))

    def describe(self) -> str:
        return f"synthetic moving box {self.width}x{self.height} at {self.fps:g} fps (simulation)"

    def open(self) -> None:
        self._pacer.reset()

    def render(self, n: int) -> np.ndarray:
        """Frame n: the box bounces across the road at `speed_px_s`."""
        image = self._background.copy()
        travel = self.width - self.box
        x = int(self.speed_px_s * n / self.fps) % (2 * travel)
        x = x if x <= travel else 2 * travel - x
        y = self.height // 2 + self.height // 8 - self.box // 2
        image[y:y + self.box, x:x + self.box] = self._texture
        return image

    def read(self) -> Frame:
        if self.frames and self._n >= self.frames:
            raise EndOfStream(f"synthetic scene ended after {self.frames} frames")
        image = self.render(self._n)
        self._n += 1
        self._pacer.wait()
        return Frame(image=image, stamp_ns=self._wall())


def road_scene(width: int, height: int) -> np.ndarray:
    """Sky gradient above the horizon, grey road with dashed lane marks below (BGR)."""
    horizon = height // 2
    image = np.empty((height, width, 3), np.uint8)
    shade = np.linspace(235, 160, horizon, dtype=np.float32)[:, None]
    image[:horizon] = np.stack([shade, shade - 30, shade - 80], axis=2).clip(0, 255)
    image[horizon:] = (90, 90, 90)
    cx = width // 2
    for side in (-1, 1):
        far = (cx + side * width // 40, horizon)
        near = (cx + side * width // 2, height - 1)
        cv2.line(image, far, near, (235, 235, 235), 3)
    for i in range(6):
        y0 = horizon + (height - horizon) * i // 6
        y1 = y0 + (height - horizon) // 12
        cv2.line(image, (cx, y0), (cx, y1), (230, 230, 230), 2)
    return image


def checkerboard(size: int, cell: int) -> np.ndarray:
    """A dark/light (BGR) checkerboard texture, size x size."""
    idx = (np.arange(size) // cell) % 2
    board = (idx[:, None] ^ idx[None, :]).astype(np.uint8)
    texture = np.where(board[:, :, None] == 1, np.uint8(200), np.uint8(40))
    return np.repeat(texture, 3, axis=2).astype(np.uint8)


def moving_box(context: SyntheticContext) -> MovingBoxSource:
    """The built-in factory. Options: `frames` (0: endless), `box_size_px`, `speed_px_s`."""
    allowed = {"frames", "box_size_px", "speed_px_s"}
    unknown = set(context.options) - allowed
    if unknown:
        raise SourceConfigError(f"moving_box: unknown options {sorted(unknown)}; "
                                f"allowed: {sorted(allowed)}")
    opts = context.options
    return MovingBoxSource(context.width, context.height, context.fps,
                           frames=int(opts.get("frames", 0)),
                           box_size_px=int(opts.get("box_size_px", 96)),
                           speed_px_s=float(opts.get("speed_px_s", 120.0)))
