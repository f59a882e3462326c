"""Synthetic source plugins for the tests (loaded by "module:factory", like the
simulator's): a camera that stalls and fails, to exercise health and reopening."""

import time

from aeb_radar_camera.services.camera.plugin import PluginContext
from aeb_radar_camera.services.camera.source import Frame, SourceError
from aeb_radar_camera.tools.sim.moving_box import MovingBoxSource


class StallingSource(MovingBoxSource):
    """Delivers `frames_per_open` frames after each open, then delivers nothing for
    `stall_s` (a hung USB camera) and fails like a device read timeout. A SIMULATION."""

    def __init__(self, context: PluginContext) -> None:
        assert context.calibration is not None
        super().__init__(context.calibration, context.fps)
        self.frames_per_open = int(context.options.get("frames_per_open", 5))
        self.stall_s = float(context.options.get("stall_s", 1.0))
        self._left = 0

    def open(self) -> None:
        super().open()
        self._left = self.frames_per_open

    def read(self) -> Frame:
        if self._left == 0:
            time.sleep(self.stall_s)   # the device delivers nothing for a while
            raise SourceError(f"no frame within {self.stall_s} s")
        self._left -= 1
        return super().read()


def stalling(context: PluginContext) -> StallingSource:
    return StallingSource(context)
