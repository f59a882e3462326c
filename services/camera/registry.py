"""The sources by `[camera.source] kind`: each built from its config, its module imported
only when used (pyrealsense2 is an optional extra)."""

from typing import TYPE_CHECKING

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.config import camera as cfg
from aeb_radar_camera.services.camera.source import FrameSource, SourceConfigError

if TYPE_CHECKING:
    from aeb_radar_camera.common.bus import Bus


def check_source(settings: cfg.CameraSettings) -> None:
    """Checks that need no bus, so that main fails fast: a plugin's factory must import,
    the realsense source needs pyrealsense2. Raises SourceConfigError."""
    if isinstance(settings.source, cfg.RealSenseSource):
        from aeb_radar_camera.services.camera.realsense import import_pyrealsense2

        import_pyrealsense2()
    if isinstance(settings.source, cfg.SyntheticSource):
        from aeb_radar_camera.services.camera.plugin import load_factory

        load_factory(settings.source.factory)


def build_source(settings: cfg.CameraSettings, cal: Calibration,
                 bus: "Bus | None" = None) -> FrameSource:
    """The source for `settings.source`; a source `fps` of 0 means the camera's fps.

    Raises SourceConfigError (bad plugin, bad options). Opening is left to the camera.
    """
    src = settings.source
    try:
        if isinstance(src, cfg.FolderSource):
            from aeb_radar_camera.services.camera.folder import FolderSource

            return FolderSource(src.path, src.fps or settings.fps, src.loop, src.extensions)
        if isinstance(src, cfg.OpenCVSource):
            from aeb_radar_camera.services.camera.opencv_capture import OpenCVSource

            return OpenCVSource(src.device, fps=src.fps, fallback_fps=settings.fps,
                                loop=src.loop, backend=src.backend, width=src.width,
                                height=src.height, timeout_ms=src.timeout_ms)
        if isinstance(src, cfg.RealSenseSource):
            from aeb_radar_camera.services.camera.realsense import RealSenseSource

            return RealSenseSource(serial=src.serial, bag=src.bag, loop=src.loop,
                                   width=src.width, height=src.height,
                                   fps=src.fps or round(settings.fps),
                                   timeout_ms=src.timeout_ms, depth=src.depth)
        from aeb_radar_camera.services.camera.plugin import PluginContext, make_plugin_source

        context = PluginContext(width=cal.width, height=cal.height,
                                fps=src.fps or settings.fps, calibration=cal,
                                camera=settings.name, options=dict(src.options), bus=bus)
        return make_plugin_source(src.factory, context)
    except ValueError as exc:
        if isinstance(exc, SourceConfigError):
            raise
        raise SourceConfigError(str(exc)) from exc
