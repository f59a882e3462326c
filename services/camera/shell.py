"""The camera on the bus: frames on CAMERA_JPEG, their depth (when the source has it
and `[camera.depth] publish`) on CAMERA_DEPTH, CameraInfo at a fixed period on
CAMERA_INFO and as a queryable on the same key, and the health token."""

import logging
import threading

import zenoh

from aeb_radar_camera.common import systemd
from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.config.camera import CameraSettings
from aeb_radar_camera.common.keys import CAMERA_DEPTH, CAMERA_INFO, CAMERA_JPEG
from aeb_radar_camera.common.log import kv
from aeb_radar_camera.common.messages import CameraInfo, Header
from aeb_radar_camera.common.systemd import Watchdog
from aeb_radar_camera.services.camera.core import Backoff, CameraCore, Health, camera_info
from aeb_radar_camera.services.camera.pipeline import FramePipeline
from aeb_radar_camera.services.camera.source import FrameSource

_log = logging.getLogger("camera")

EXIT_OK = 0
EXIT_CONFIG = 2


class CameraShell:
    """Wires a source, the pipeline and the bus. Use `run(stop)` from the main thread."""

    def __init__(self, settings: CameraSettings, cal: Calibration, source: FrameSource,
                 bus: Bus, watchdog: Watchdog | None = None) -> None:
        self.settings = settings
        self.watchdog = watchdog or Watchdog(env={})   # fed by the info loop of `run`
        self.cal = cal
        self.bus = bus
        self.core = CameraCore(settings.name, cal.width, cal.height, settings.fps,
                               settings.depth.fps)
        self.health = Health(settings.stall_timeout_s)
        frames = bus.publisher(CAMERA_JPEG, camera=settings.name)
        depth = (bus.publisher(CAMERA_DEPTH, camera=settings.name)
                 if settings.depth.publish else None)
        self.pipeline = FramePipeline(
            source, self.core, self.health,
            Backoff(settings.reopen_initial_s, settings.reopen_max_s),
            publish=frames.put, jpeg_quality=settings.jpeg_quality,
            publish_depth=depth.put if depth is not None else None, depth=settings.depth,
        )
        self._info_pub = bus.publisher(CAMERA_INFO, camera=settings.name)
        self._info_seq = 0
        self._queryable: zenoh.Queryable[None] | None = None
        self._token: zenoh.LivelinessToken | None = None

    def info(self) -> CameraInfo:
        """The current CameraInfo, stamped now (thread-safe: also called from Zenoh's
        query threads)."""
        now = mono_ns()
        with self.pipeline.lock:
            healthy, status = self.health.status(now, self.core.last_rejection)
            header = Header(seq=self._info_seq, source=self.core.source_name,
                            stamp_ns=wall_ns(), pub_mono_ns=now)
            self._info_seq += 1
            return camera_info(self.cal, self.settings.name, self.settings.fps,
                               self.pipeline.source.kind, self.core.stats,
                               self.pipeline.source.skipped, healthy, status,
                               self.health.reopens, header)

    def run(self, stop: threading.Event) -> int:
        """Serve until `stop`, the end of a finite source with `exit_at_end`, or an
        unusable source (exit code 2)."""
        self._queryable = self.bus.declare_queryable(CAMERA_INFO, self.info,
                                                     camera=self.settings.name)
        self.pipeline.start()
        self._token = self.bus.declare_health("camera", self.settings.name)
        systemd.ready(f"serving camera {self.settings.name}")
        _log.info(kv("camera_serving", camera=self.settings.name,
                     source=self.pipeline.source.describe(), fps=self.settings.fps,
                     size=f"{self.cal.width}x{self.cal.height}"))
        period = self.settings.info_period_s
        next_stats = mono_ns() + round(self.settings.stats_period_s * 1e9)
        try:
            while True:
                self._info_pub.put(self.info())
                if self.pipeline.fatal is not None:
                    return EXIT_CONFIG
                if self.pipeline.ended.is_set() and self.settings.exit_at_end:
                    self.pipeline.wait_idle(timeout_s=5.0)   # publish the last frame
                    self._info_pub.put(self.info())
                    return EXIT_OK
                if self.settings.stats_period_s and mono_ns() >= next_stats:
                    next_stats = mono_ns() + round(self.settings.stats_period_s * 1e9)
                    self.log_stats()
                if self.watchdog.wait(stop, period):
                    return EXIT_OK
        finally:
            self.close()

    def log_stats(self) -> None:
        with self.pipeline.lock:
            s = self.core.stats
            timing = self.pipeline.timing
            healthy, status = self.health.status(mono_ns(), self.core.last_rejection)
            _log.info(kv("camera_stats", captured=s.captured, published=s.published,
                         dropped=s.dropped, decimated=s.decimated,
                         read_errors=s.errors.total() + self.pipeline.source.skipped,
                         rate_hz=timing.publish_rate_hz(), encode_ms_p50=timing.encode_ms(50),
                         encode_ms_p95=timing.encode_ms(95), healthy=healthy, status=status))

    def close(self) -> None:
        if self._token is not None:
            self._token.undeclare()
            self._token = None
        self.pipeline.stop()
        if self._queryable is not None:
            self._queryable.undeclare()
            self._queryable = None
