"""The camera's two threads around the pure core.

- capture: opens the source (reopening with backoff after a failure), reads frames and
  offers them to the core's one-frame slot. It never waits for the encoder or the bus.
- publish: takes the newest frame from the slot, encodes it to JPEG and hands the
  message to `publish`; then, when the frame has depth and depth is published, its
  depth (decimated, coded losslessly: common/depth_image.py) to `publish_depth` with the
  same capture stamp. While it is busy, newer frames replace the pending one (counted
  as dropped): a slow encoder or bus never builds a backlog. A depth image that is not
  uint16 of the frame's size is counted (`depth_error`) and not published; the frame is.

`publish` must not block for long (the Zenoh publisher uses congestion control DROP);
it may raise zenoh.ZError, which is counted and logged.
"""

import logging
import threading
from collections import deque
from collections.abc import Callable

import numpy as np
import zenoh

from aeb_radar_camera.common.clock import NS_PER_MS, mono_ns
from aeb_radar_camera.common.config.camera import DepthSettings
from aeb_radar_camera.common.depth_image import encode_depth
from aeb_radar_camera.common.imaging import encode_jpeg
from aeb_radar_camera.common.log import RateLimitedLog, kv
from aeb_radar_camera.common.messages import CompressedFrame, DepthFrame
from aeb_radar_camera.services.camera.core import Backoff, CameraCore, Health, Offer
from aeb_radar_camera.services.camera.source import (
    EndOfStream,
    Frame,
    FrameSource,
    SourceConfigError,
)

_log = logging.getLogger("camera")

Encoder = Callable[[np.ndarray, int], bytes]


class Timing:
    """Recent encode durations and publish instants, for the stats log and benchmarks
    (read and written under the pipeline's lock)."""

    def __init__(self, window: int = 300) -> None:
        self.encode_ns: deque[int] = deque(maxlen=window)
        self.publish_mono_ns: deque[int] = deque(maxlen=window)

    def encode_ms(self, pct: float) -> float:
        if not self.encode_ns:
            return float("nan")
        return float(np.percentile(np.array(self.encode_ns), pct)) / NS_PER_MS

    def publish_rate_hz(self) -> float:
        stamps = self.publish_mono_ns
        if len(stamps) < 2 or stamps[-1] == stamps[0]:
            return 0.0
        return (len(stamps) - 1) * 1e9 / (stamps[-1] - stamps[0])


class FramePipeline:
    """Capture and publish threads for one source. `lock` guards core and health."""

    def __init__(self, source: FrameSource, core: CameraCore, health: Health,
                 backoff: Backoff, publish: Callable[[CompressedFrame], None],
                 jpeg_quality: int = 80, encode: Encoder = encode_jpeg,
                 clock: Callable[[], int] = mono_ns,
                 publish_depth: Callable[[DepthFrame], None] | None = None,
                 depth: DepthSettings | None = None) -> None:
        self.source = source
        self.core = core
        self.health = health
        self.backoff = backoff
        self.timing = Timing()
        self.lock = threading.Condition()
        self.ended = threading.Event()
        self.fatal: SourceConfigError | None = None
        self._publish = publish
        self._publish_depth = publish_depth
        self._depth = depth or DepthSettings()
        self._quality = jpeg_quality
        self._encode = encode
        self._clock = clock
        self._stopping = threading.Event()
        self._busy = False   # the publish thread holds a frame (guarded by lock)
        self._rl = RateLimitedLog(_log)
        self._threads = [
            threading.Thread(target=self._capture_loop, name="camera-capture", daemon=True),
            threading.Thread(target=self._publish_loop, name="camera-publish", daemon=True),
        ]

    @property
    def finished(self) -> bool:
        """The source ended or can never work: nothing more will be published."""
        return self.ended.is_set() or self.fatal is not None

    def start(self) -> None:
        for t in self._threads:
            t.start()

    def wait_idle(self, timeout_s: float) -> bool:
        """Wait until no frame is pending or being encoded/published (e.g. to flush the
        last frame of a finished source). Returns False on timeout."""
        with self.lock:
            return self.lock.wait_for(
                lambda: self.core.pending is None and not self._busy, timeout_s)

    def stop(self, timeout_s: float = 3.0) -> None:
        """Stop both threads. A source blocked in read() longer than `timeout_s` is left
        to its daemon thread (the process is exiting anyway)."""
        self._stopping.set()
        with self.lock:
            self.lock.notify_all()
        for t in self._threads:
            t.join(timeout_s)

    def _capture_loop(self) -> None:
        try:
            while not self._stopping.is_set() and not self.finished:
                self._stream()
        finally:
            self.source.close()
            with self.lock:
                self.lock.notify_all()

    def _stream(self) -> None:
        """Open the source and read it until it ends, fails or the pipeline stops. A
        failure is reported (the camera is down) and the source reopened after a backoff;
        SourceConfigError is fatal."""
        step = "open"
        try:
            self.source.open()
            with self.lock:
                self.health.streaming(self._clock())
            _log.info(kv("source_open", source=self.source.describe()))
            step = "read"
            self._read_until_end()
        except SourceConfigError as exc:
            self._fatal(exc)
        except EndOfStream as exc:
            with self.lock:
                self.health.ended()
            _log.info(kv("end_of_stream", detail=str(exc)))
            self.ended.set()   # the publish thread still sends the pending frame
        except Exception as exc:  # SourceError, or a source's bug: report it down, never die
            if step == "read":
                self.source.close()
            self._failed(step, exc)

    def _read_until_end(self) -> None:
        """Read and offer frames until the pipeline stops. Raises what the source raises."""
        first = True
        while not self._stopping.is_set():
            frame = self.source.read()
            now = self._clock()
            with self.lock:
                result = self.core.offer(frame, now)
                if result is Offer.REJECTED:
                    self._rl.warning("rejected", "frame_rejected", reason=self.core.last_rejection)
                    continue
                self.health.frame(now)
                if result is Offer.PENDING:
                    self.lock.notify_all()   # the publish thread, and wait_idle callers
            if first:
                self.backoff.reset()
                first = False

    def _failed(self, what: str, exc: Exception) -> None:
        delay = self.backoff.next_delay()
        error = f"{what}: {exc}" if str(exc) else f"{what}: {type(exc).__name__}"
        with self.lock:
            self.core.stats.errors.add("source_error")
            self.health.failed(error, delay)
        self._rl.warning("source_failed", "source_failed", error=error,
                         kind=type(exc).__name__, source=self.source.describe(),
                         retry_in_s=delay)
        self._stopping.wait(delay)

    def _fatal(self, exc: SourceConfigError) -> None:
        _log.error(kv("source_unusable", error=str(exc)))
        self.fatal = exc

    def _publish_loop(self) -> None:
        while True:
            with self.lock:
                while not self._stopping.is_set() and self.core.pending is None:
                    self.lock.wait()
                if self._stopping.is_set():
                    return
                frame = self.core.take()
                self._busy = True
            assert frame is not None
            try:
                self._encode_and_publish(frame)
            finally:
                with self.lock:
                    self._busy = False
                    self.lock.notify_all()

    def _encode_and_publish(self, frame: Frame) -> None:
        t0 = self._clock()
        try:
            jpeg = self._encode(frame.image, self._quality)
        except ValueError as exc:
            with self.lock:
                self.core.stats.errors.add("encode_error")
            self._rl.error("encode", "encode_failed", error=repr(exc))
            return
        t1 = self._clock()
        with self.lock:
            msg = self.core.message(frame, jpeg, self._clock())
        try:
            self._publish(msg)
        except zenoh.ZError as exc:
            with self.lock:
                self.core.stats.errors.add("publish_error")
            self._rl.error("publish", "publish_failed", error=repr(exc))
            return
        with self.lock:
            self.timing.encode_ns.append(t1 - t0)
            self.timing.publish_mono_ns.append(msg.header.pub_mono_ns)
        if frame.depth is not None and self._publish_depth is not None:
            self._encode_and_publish_depth(frame, frame.depth)

    def _encode_and_publish_depth(self, frame: Frame, depth: np.ndarray) -> None:
        with self.lock:
            due = self.core.depth_due(self._clock())
        if not due:
            return
        k = self._depth.decimation
        try:
            if depth.shape != frame.image.shape[:2]:
                raise ValueError(f"depth is {depth.shape}, frame {frame.image.shape[:2]}")
            units = depth[::k, ::k] if k > 1 else depth
            data = encode_depth(units, self._depth.codec)
        except ValueError as exc:
            with self.lock:
                self.core.stats.errors.add("depth_error")
            self._rl.error("depth", "depth_encode_failed", error=repr(exc))
            return
        with self.lock:
            msg = self.core.depth_message(frame, data, self._depth.codec, units.shape[1],
                                          units.shape[0], self._clock())
        try:
            assert self._publish_depth is not None
            self._publish_depth(msg)
        except zenoh.ZError as exc:
            with self.lock:
                self.core.stats.errors.add("publish_error")
            self._rl.error("publish", "publish_failed", error=repr(exc))
