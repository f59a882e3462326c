"""Camera frames for fusion: decoded to grayscale in a worker thread per camera, into a
small ring of recent frames; and the pure choice of the frame for a radar cycle.

The radar callback never waits for a JPEG decode: it takes a snapshot of the ring and
works on frames already decoded. Decoding goes through common.imaging.decode_gray, the
project's one path.

Depth (when the verifier needs it): each DepthFrame is decoded in the same worker
(common/depth_image.py, the one depth path), brought to the frame's size (nearest
neighbour: every depth pixel covers its block of colour pixels) and paired with the
colour frame of the same capture stamp, whichever of the two arrives first. A frame
without its depth stays in the ring without depth (a depth verifier does not use it).
"""

import logging
import math
import threading
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace

import cv2
import numpy as np

from aeb_radar_camera.common.clock import mono_ns
from aeb_radar_camera.common.depth_image import DepthDecodeError, decode_depth, to_metres
from aeb_radar_camera.common.imaging import ImageCorruptError, ImageDecodeError, decode_gray
from aeb_radar_camera.common.log import RateLimitedLog
from aeb_radar_camera.common.messages import (
    CompressedFrame,
    DecodeError,
    DepthFrame,
    RadarTrack,
    decode,
)
from aeb_radar_camera.services.fusion.roi import ColumnProjector

# Decoded frames kept per camera: a cycle uses the one nearest its stamp, which within the
# skew bound is one of the last few at 30 fps.
RING_SIZE = 4
# Frames waiting for the decoder; when full the oldest is dropped (and counted): a newer
# frame is always worth more than a backlog.
QUEUE_SIZE = 2
# Two pictures are the same when their low-pass images (the mean of each COARSE_CELL x
# COARSE_CELL block) differ nowhere by more than SAME_MAX_CELL_DIFF grey levels, but in
# fewer than SAME_MIN_CELLS cells. Block means are blind to i.i.d. sensor noise (sigma 2
# grey levels per pixel is 0.18 in the difference of two 16 x 16 means; JPEG's rounding of
# the block means about as much), and not to motion: an edge of contrast 20 moved by
# 4 pixels changes the cells it crosses by 5 levels. A live sensor on a still scene is
# therefore "the same picture" too: whether a camera is frozen is decided against what
# the tracks say the picture must do (`frozen`), never on pixel identity.
COARSE_CELL = 16
SAME_MAX_CELL_DIFF = 2.0
SAME_MIN_CELLS = 2


def coarse(gray: np.ndarray) -> np.ndarray:
    """The low-pass image of a grayscale frame: float32 block means (pure)."""
    h, w = gray.shape
    return cv2.resize(gray, (max(1, w // COARSE_CELL), max(1, h // COARSE_CELL)),
                      interpolation=cv2.INTER_AREA).astype(np.float32)


def same_picture(a: np.ndarray, b: np.ndarray) -> bool:
    """Do two low-pass images (`coarse`) show the same picture, up to sensor noise? (pure)"""
    if a.shape != b.shape:
        return False
    return int(np.count_nonzero(np.abs(a - b) > SAME_MAX_CELL_DIFF)) < SAME_MIN_CELLS


@dataclass(frozen=True, slots=True)
class DecodedFrame:
    camera: str
    seq: int
    stamp_ns: int          # capture time (wall clock)
    rx_mono_ns: int        # when fusion received it
    gray: np.ndarray       # 2-D uint8, never modified after decoding
    depth_m: np.ndarray | None = None   # float32 metres at gray's size, 0 = no return


@dataclass(frozen=True, slots=True)
class FrameFeed:
    """What the decoder holds at one instant: recent frames (oldest first) and counters."""

    frames: tuple[DecodedFrame, ...] = ()
    received: int = 0
    undecodable: int = 0
    dropped: int = 0
    last_error: str = ""
    last_error_rx_mono_ns: int | None = None
    corrupt: int = 0       # of `undecodable`: bytes not matching the camera's CRC-32
    # capture stamp of the first of the newest decoded frames whose pictures are all the
    # same as it up to sensor noise (`same_picture`); None when the newest differs from it
    unchanged_since_ns: int | None = None
    # set by fusion's core: this camera is not to be used this cycle, and why
    unusable_reason: str = ""
    depth_received: int = 0
    depth_undecodable: int = 0
    depth_dropped: int = 0


class FrameError(ValueError):
    """A frame that cannot be used; `reason` is a short counter name."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


def decode_frame(payload: bytes, rx_mono_ns: int, width: int, height: int) -> DecodedFrame:
    """A CompressedFrame payload to a grayscale frame of the calibration's size.

    Raises FrameError (reasons: "message", "corrupt" (CRC-32 mismatch), "jpeg", "size").
    """
    try:
        msg = decode(payload, CompressedFrame)
    except DecodeError as exc:
        raise FrameError("message", str(exc)) from exc
    if (msg.width, msg.height) != (width, height):
        raise FrameError("size", f"frame is {msg.width}x{msg.height}, calibration "
                                 f"{width}x{height}")
    try:
        gray = decode_gray(msg.jpeg, width, height, msg.crc32)
    except ImageCorruptError as exc:
        raise FrameError("corrupt", f"frame seq {msg.header.seq}: {exc}") from exc
    except ImageDecodeError as exc:
        raise FrameError("jpeg", f"frame seq {msg.header.seq}: {exc}") from exc
    return DecodedFrame(msg.camera, msg.header.seq, msg.header.stamp_ns, rx_mono_ns, gray)


FROZEN_REASON = "camera frozen"
# A live camera's picture must change where a confirmed track's column moves or grows by
# at least this many pixels in its image: half a cell of the low-pass image, an edge of
# contrast 4 grey levels moved that far changes every cell it crosses by more than
# SAME_MAX_CELL_DIFF. (A car closing at 8 m/s from 20 m: its column's foot moves 10 px in
# 0.5 s in the example calibration; from 12 m, 16 px.)
EXPECTED_CHANGE_MIN_PX = 8.0
# The tracks are predicted back (constant velocity) over at most this many times
# `frozen_after_s` of one picture: further back the prediction says little.
EXPECTED_CHANGE_SPAN = 2


def frozen(feed: FrameFeed, expected_change_px: float, frozen_after_ns: int) -> bool:
    """Has this camera shown the same picture (`same_picture`) for `frozen_after_ns` of
    capture time while the tracks moved its image by `expected_change_px` (see
    `expected_change`) over that time? (pure; `frozen_after_ns` 0: never)"""
    window = unchanged_for_ns(feed)
    return (bool(frozen_after_ns) and window is not None and window >= frozen_after_ns
            and expected_change_px >= EXPECTED_CHANGE_MIN_PX)


def unchanged_for_ns(feed: FrameFeed) -> int | None:
    """How long (capture time) the newest frame's picture has been the same, or None."""
    if feed.unchanged_since_ns is None or not feed.frames:
        return None
    return max(f.stamp_ns for f in feed.frames) - feed.unchanged_since_ns


def expected_change_px(projector: ColumnProjector, tracks: Sequence[RadarTrack],
                       span_ns: int) -> float:
    """The most that any track's column (its clipped box in the image) moved or grew, in
    pixels, over the last `span_ns` of constant-velocity motion relative to the ego
    (pure). Tracks seen in the image at only one end of the span do not count: a ghost
    track or a track entering the view proves nothing about the picture."""
    moving = [t for t in tracks if math.hypot(t.vx_mps, t.vy_mps) * span_ns > 0.0]
    if not moving or span_ns <= 0:
        return 0.0
    dt = span_ns / 1e9
    now = np.array([(t.x_m, t.y_m) for t in moving], dtype=np.float64)
    then = now - dt * np.array([(t.vx_mps, t.vy_mps) for t in moving], dtype=np.float64)
    boxes = projector.boxes(np.concatenate([now, then]))
    most = 0.0
    for a, b in zip(boxes[:len(moving)], boxes[len(moving):], strict=True):
        if a is not None and b is not None:
            ca, cb = a[1], b[1]
            most = max(most, abs(ca.x - cb.x), abs(ca.y - cb.y),
                       abs(ca.x + ca.w - cb.x - cb.w), abs(ca.y + ca.h - cb.y - cb.h))
    return float(most)


def decode_depth_frame(payload: bytes, width: int, height: int) -> tuple[int, np.ndarray]:
    """A DepthFrame payload to (capture stamp, float32 metres at width x height).

    The depth may be smaller than the frame by a whole factor (the camera's decimation).
    Raises FrameError (reasons: "depth_message", "depth_size", "depth_codec").
    """
    try:
        msg = decode(payload, DepthFrame)
    except DecodeError as exc:
        raise FrameError("depth_message", str(exc)) from exc
    fx, fy = (width // msg.width, height // msg.height) if msg.width and msg.height else (0, 0)
    if fx < 1 or fx != fy or (msg.width * fx, msg.height * fy) != (width, height):
        raise FrameError("depth_size", f"depth is {msg.width}x{msg.height}, not the frame's "
                                       f"{width}x{height} divided by a whole factor")
    try:
        units = decode_depth(msg.data, msg.codec, msg.width, msg.height)
    except DepthDecodeError as exc:
        raise FrameError("depth_codec", f"depth seq {msg.header.seq}: {exc}") from exc
    depth = to_metres(units, msg.units_m)
    if fx > 1:
        depth = cv2.resize(depth, (width, height), interpolation=cv2.INTER_NEAREST)
    return msg.header.stamp_ns, depth


def select_frame(frames: tuple[DecodedFrame, ...], radar_stamp_ns: int, max_skew_ns: int,
                 align: bool) -> DecodedFrame | None:
    """The frame to verify a radar cycle with, or None.

    align: the frame nearest in capture time to the radar cycle. Otherwise (the paper):
    the newest frame. Either way the frame must be within max_skew_ns of the cycle.
    """
    if not frames:
        return None
    if align:
        best = min(frames, key=lambda f: abs(f.stamp_ns - radar_stamp_ns))
    else:
        best = max(frames, key=lambda f: f.rx_mono_ns)
    return best if abs(best.stamp_ns - radar_stamp_ns) <= max_skew_ns else None


def unavailable_reason(feed: FrameFeed, radar_stamp_ns: int, max_skew_ns: int) -> str:
    """Why no frame could be used for this cycle (for people and logs)."""
    newest = max(feed.frames, key=lambda f: f.rx_mono_ns) if feed.frames else None
    if feed.last_error_rx_mono_ns is not None and (
            newest is None or feed.last_error_rx_mono_ns > newest.rx_mono_ns):
        return f"newest frame unusable: {feed.last_error}"
    if newest is None:
        return "no camera frame received"
    nearest = min(feed.frames, key=lambda f: abs(f.stamp_ns - radar_stamp_ns))
    skew_ms = (nearest.stamp_ns - radar_stamp_ns) / 1e6
    return (f"nearest frame {skew_ms:+.0f} ms from the radar cycle "
            f"(max {max_skew_ns / 1e6:.0f} ms)")


class FrameDecoder:
    """Decodes one camera's frames in its own thread; `submit` (from Zenoh's thread)
    never blocks."""

    def __init__(self, width: int, height: int, log: logging.Logger, camera: str = "") -> None:
        self.width = width
        self.height = height
        self.camera = camera
        self._pending: deque[tuple[bytes, int]] = deque()
        self._depth_pending: deque[bytes] = deque()
        # Decoded depth still waiting for its frame, by capture stamp.
        self._depth_waiting: deque[tuple[int, np.ndarray]] = deque(maxlen=RING_SIZE)
        self._ring: deque[DecodedFrame] = deque(maxlen=RING_SIZE)
        self._cond = threading.Condition()
        self._received = 0
        self._undecodable = 0
        self._dropped = 0
        self._depth_received = 0
        self._depth_undecodable = 0
        self._depth_dropped = 0
        self._last_error = ""
        self._last_error_rx: int | None = None
        self._unchanged_since: int | None = None
        # the first frame of the current run of one picture: its stamp and low-pass image.
        # Each frame is compared with it, not with the one before, so that a slow change
        # (a far car growing a pixel a frame) adds up until it shows
        self._reference: tuple[int, np.ndarray] | None = None
        self.errors_by_reason: dict[str, int] = {}
        self._stop = False
        self._thread = threading.Thread(target=self._run, daemon=True,
                                        name=f"frame-decoder-{camera}" if camera
                                        else "frame-decoder")
        self._log = log
        self._rl = RateLimitedLog(log)

    def start(self) -> None:
        self._thread.start()

    @property
    def thread_ident(self) -> int | None:
        """The worker thread's ident once started (for per-thread CPU accounting)."""
        return self._thread.ident

    def stop(self, timeout_s: float = 2.0) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self._thread.is_alive():
            self._thread.join(timeout_s)

    def submit(self, payload: bytes, key: str, rx_mono_ns: int) -> None:
        """Queue a raw CompressedFrame; when the queue is full the oldest waiting frame is
        dropped (and counted): a newer frame is always worth more."""
        with self._cond:
            self._received += 1
            if len(self._pending) >= QUEUE_SIZE:
                self._pending.popleft()
                self._dropped += 1
            self._pending.append((payload, rx_mono_ns))
            self._cond.notify()

    def submit_depth(self, payload: bytes, key: str, rx_mono_ns: int) -> None:
        """Queue a raw DepthFrame (never blocks); when the queue is full the oldest waiting
        one is dropped and counted."""
        with self._cond:
            self._depth_received += 1
            if len(self._depth_pending) >= QUEUE_SIZE:
                self._depth_pending.popleft()
                self._depth_dropped += 1
            self._depth_pending.append(payload)
            self._cond.notify()

    def decode_now(self, payload: bytes, rx_mono_ns: int) -> None:
        """Decode one payload in the caller's thread (the worker's body; also for tests)."""
        try:
            frame = decode_frame(payload, rx_mono_ns, self.width, self.height)
        except FrameError as exc:
            self._unusable(exc.reason, str(exc), rx_mono_ns)
            self._rl.warning(f"frame:{exc.reason}", "frame_unusable", reason=exc.reason,
                             camera=self.camera, error=str(exc))
            return
        low = coarse(frame.gray)
        with self._cond:
            if self._reference is not None and same_picture(self._reference[1], low):
                self._unchanged_since = self._reference[0]
            else:
                self._reference = (frame.stamp_ns, low)
                self._unchanged_since = None
            for i, (stamp, depth) in enumerate(self._depth_waiting):
                if stamp == frame.stamp_ns:
                    del self._depth_waiting[i]
                    frame = replace(frame, depth_m=depth)
                    break
            self._ring.append(frame)

    def decode_depth_now(self, payload: bytes) -> None:
        """Decode one DepthFrame and pair it with its frame (the worker's body)."""
        try:
            stamp, depth = decode_depth_frame(payload, self.width, self.height)
        except FrameError as exc:
            with self._cond:
                self._depth_undecodable += 1
                self.errors_by_reason[exc.reason] = self.errors_by_reason.get(exc.reason,
                                                                              0) + 1
            self._rl.warning(f"depth:{exc.reason}", "depth_unusable", reason=exc.reason,
                             camera=self.camera, error=str(exc))
            return
        with self._cond:
            for i, frame in enumerate(self._ring):
                if frame.stamp_ns == stamp:
                    self._ring[i] = replace(frame, depth_m=depth)
                    return
            self._depth_waiting.append((stamp, depth))

    def _unusable(self, reason: str, error: str, rx_mono_ns: int) -> None:
        with self._cond:
            self._undecodable += 1
            self.errors_by_reason[reason] = self.errors_by_reason.get(reason, 0) + 1
            self._last_error = error
            self._last_error_rx = rx_mono_ns

    def _next(self) -> tuple[bytes, int] | bytes | None:
        """The next frame or depth payload to decode, depth first (None: stopping)."""
        with self._cond:
            while True:
                if self._stop:
                    return None
                if self._depth_pending:
                    return self._depth_pending.popleft()
                if self._pending:
                    return self._pending.popleft()
                self._cond.wait()

    def _run(self) -> None:
        while True:
            item = self._next()
            if item is None:
                return
            try:
                if isinstance(item, bytes):
                    self.decode_depth_now(item)
                else:
                    self.decode_now(*item)
            except Exception as exc:  # a bug must not end this camera's frames: count, go on
                self._unusable("decoder_error", f"decoder error: {exc!r}",
                               mono_ns() if isinstance(item, bytes) else item[1])
                self._rl.error("frame:bug", "frame_decoder_failed", camera=self.camera,
                               error=repr(exc))

    def snapshot(self) -> FrameFeed:
        with self._cond:
            return FrameFeed(tuple(self._ring), self._received, self._undecodable,
                             self._dropped, self._last_error, self._last_error_rx,
                             corrupt=self.errors_by_reason.get("corrupt", 0),
                             unchanged_since_ns=self._unchanged_since,
                             depth_received=self._depth_received,
                             depth_undecodable=self._depth_undecodable,
                             depth_dropped=self._depth_dropped)
