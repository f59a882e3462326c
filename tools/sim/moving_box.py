"""The moving-box demo scene: a camera plugin (services/camera/plugin.py) that renders a
cardboard box sliding from side to side across the road ahead. A SIMULATION, for demos
and for trying the camera and fusion without hardware; the real sources are RealSense,
OpenCV captures and image folders.

Camera config (deploy/camera-sim.toml)::

    [camera.source]
    kind = "synthetic"
    factory = "aeb_radar_camera.tools.sim.moving_box:make_source"
    options = { distance_m = 10.0, speed_mps = 1.0 }
"""

import math
import time
from collections.abc import Callable

import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.clock import wall_ns
from aeb_radar_camera.services.camera.plugin import PluginContext
from aeb_radar_camera.services.camera.source import (
    EndOfStream,
    Frame,
    FrameSource,
    Pacer,
    SourceConfigError,
)
from aeb_radar_camera.tools.messages import ObjectKind
from aeb_radar_camera.tools.sim.render import Renderer
from aeb_radar_camera.tools.sim.scenario import DEFAULT_SIZE, CameraLook
from aeb_radar_camera.tools.sim.world import Body

# The box goes this far to either side of the lane's centre line.
HALF_SWEEP_M = 3.0


class MovingBoxSource(FrameSource):
    """A cardboard box `distance_m` ahead, moving across the road at `speed_mps` and back.

    Deterministic: frame n is the same image on every run. `frames` > 0 makes the source
    finite (EndOfStream after that many frames).
    """

    kind = "synthetic"

    def __init__(self, calibration: Calibration, fps: float, frames: int = 0,
                 distance_m: float = 10.0, speed_mps: float = 1.0,
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep,
                 wall_clock: Callable[[], int] = wall_ns) -> None:
        super().__init__()
        if frames < 0 or not 1.0 <= distance_m <= 100.0 or speed_mps < 0:
            raise ValueError("frames must be >= 0, distance_m in [1, 100] and speed_mps >= 0")
        self.fps = fps
        self.frames = frames
        self.distance_m = distance_m
        self.speed_mps = speed_mps
        self.renderer = Renderer(calibration, look=CameraLook(noise=0.0), roadside=False)
        self._pacer = Pacer(fps, clock, sleep)
        self._wall = wall_clock
        self._n = 0

    def describe(self) -> str:
        return (f"moving box {self.renderer.width}x{self.renderer.height} at {self.fps:g} fps "
                "(simulation)")

    def open(self) -> None:
        self._pacer.reset()

    def render(self, n: int) -> np.ndarray:
        """Frame n: the box's offset goes back and forth over +-HALF_SWEEP_M."""
        travel = self.speed_mps * n / self.fps
        phase = math.fmod(travel, 4 * HALF_SWEEP_M)
        y = abs(phase - 2 * HALF_SWEEP_M) - HALF_SWEEP_M
        length, width, height = DEFAULT_SIZE[ObjectKind.BOX]
        box = Body(0, ObjectKind.BOX, self.distance_m + length / 2, y, 0.0, length, width,
                   height, 0.0, 0.0)
        return self.renderer.render([box], 0.0)

    def read(self) -> Frame:
        if self.frames and self._n >= self.frames:
            raise EndOfStream(f"moving box scene ended after {self.frames} frames")
        image = self.render(self._n)
        self._n += 1
        self._pacer.wait()
        return Frame(image=image, stamp_ns=self._wall())


def make_source(context: PluginContext) -> MovingBoxSource:
    """The plugin factory. Options: `frames` (0: endless), `distance_m` (10),
    `speed_mps` (1). Raises SourceConfigError for unknown options or no calibration."""
    allowed = {"frames", "distance_m", "speed_mps"}
    unknown = set(context.options) - allowed
    if unknown:
        raise SourceConfigError(f"moving_box: unknown options {sorted(unknown)}; "
                                f"allowed: {sorted(allowed)}")
    if context.calibration is None:
        raise SourceConfigError("moving_box needs the camera's calibration")
    opts = context.options
    return MovingBoxSource(context.calibration, context.fps,
                           frames=int(opts.get("frames", 0)),
                           distance_m=float(opts.get("distance_m", 10.0)),
                           speed_mps=float(opts.get("speed_mps", 1.0)))
