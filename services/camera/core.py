"""The camera's pure core: which frames to publish, the messages, health and backoff.

No threads, no clocks, no Zenoh: the shell passes the current time in and holds a lock
around calls made from its capture and publish threads.

Frames flow capture -> `offer` -> one pending slot -> `take` -> encode -> `message`.
The slot holds one frame: a newer frame replaces an unpublished one (counted as
dropped), so a slow encoder or bus never builds a backlog and what is published is
always the newest frame.
"""

import enum
from dataclasses import dataclass, field

import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.counters import ReasonCounter
from aeb_radar_camera.common.imaging import jpeg_crc32
from aeb_radar_camera.common.messages import CameraInfo, CompressedFrame, DepthFrame, Header
from aeb_radar_camera.services.camera.source import Frame

NS_PER_S = 1_000_000_000


class Offer(enum.Enum):
    PENDING = "pending"          # waiting in the slot for the encoder
    DECIMATED = "decimated"      # faster than the publish rate: skipped
    REJECTED = "rejected"        # not a usable frame (wrong size or type): counted


class RateGate:
    """Admits frames at no more than `fps`, on a fixed grid with jitter tolerance.

    A frame is admitted when it arrives no earlier than a quarter period before its slot;
    a source running at exactly `fps` with jitter is never decimated, a faster one is
    thinned evenly, and after a gap the grid restarts at the next frame (no burst).
    """

    def __init__(self, fps: float) -> None:
        self.period_ns = round(NS_PER_S / fps)
        self._tolerance_ns = self.period_ns // 4
        self._next_ns: int | None = None

    def admit(self, now_ns: int) -> bool:
        if self._next_ns is not None and now_ns < self._next_ns - self._tolerance_ns:
            return False
        if self._next_ns is None or now_ns >= self._next_ns + self.period_ns:
            self._next_ns = now_ns + self.period_ns
        else:
            self._next_ns += self.period_ns
        return True


@dataclass
class FrameStats:
    captured: int = 0       # frames the source delivered
    decimated: int = 0      # skipped to keep the publish rate
    dropped: int = 0        # replaced in the slot before the encoder took them
    published: int = 0
    depth_published: int = 0
    errors: ReasonCounter = field(default_factory=ReasonCounter)


class CameraCore:
    """Rate gate, single pending slot, sequence numbers and message building."""

    def __init__(self, camera: str, width: int, height: int, fps: float,
                 depth_fps: float = 0.0) -> None:
        self.camera = camera
        self.source_name = f"camera/{camera}"
        self.width = width
        self.height = height
        self.stats = FrameStats()
        self.last_rejection = ""
        self._gate = RateGate(fps)
        self._pending: Frame | None = None
        self._seq = 0
        # Depth goes out with the published frames, thinned to depth_fps (0: with each).
        self._depth_gate = RateGate(depth_fps) if depth_fps > 0 else None
        self._depth_seq = 0

    def offer(self, frame: Frame, now_mono_ns: int) -> Offer:
        """A frame from the source, at `now_mono_ns` (monotonic)."""
        self.stats.captured += 1
        problem = self._check(frame.image)
        if problem:
            reason, self.last_rejection = problem
            self.stats.errors.add(reason)
            return Offer.REJECTED
        self.last_rejection = ""   # only the newest frame's problem explains a stall
        if not self._gate.admit(now_mono_ns):
            self.stats.decimated += 1
            return Offer.DECIMATED
        if self._pending is not None:
            self.stats.dropped += 1
        self._pending = frame
        return Offer.PENDING

    @property
    def pending(self) -> Frame | None:
        return self._pending

    def take(self) -> Frame | None:
        """The newest unpublished frame (emptying the slot), or None."""
        frame, self._pending = self._pending, None
        return frame

    def message(self, frame: Frame, jpeg: bytes, pub_mono_ns: int) -> CompressedFrame:
        """The CompressedFrame for an encoded frame; numbers it (seq from 0, no gaps)."""
        header = Header(seq=self._seq, source=self.source_name, stamp_ns=frame.stamp_ns,
                        pub_mono_ns=pub_mono_ns)
        self._seq += 1
        self.stats.published += 1
        return CompressedFrame(header=header, camera=self.camera, width=self.width,
                               height=self.height, jpeg=jpeg, crc32=jpeg_crc32(jpeg))

    def depth_due(self, now_mono_ns: int) -> bool:
        """Whether the frame being published now also gets its depth published."""
        return self._depth_gate is None or self._depth_gate.admit(now_mono_ns)

    def depth_message(self, frame: Frame, data: bytes, codec: str, width: int, height: int,
                      pub_mono_ns: int) -> DepthFrame:
        """The DepthFrame for a frame's encoded depth: its capture stamp, its own seq."""
        header = Header(seq=self._depth_seq, source=self.source_name, stamp_ns=frame.stamp_ns,
                        pub_mono_ns=pub_mono_ns)
        self._depth_seq += 1
        self.stats.depth_published += 1
        return DepthFrame(header=header, camera=self.camera, width=width, height=height,
                          codec=codec, data=data)

    def _check(self, image: np.ndarray) -> tuple[str, str] | None:
        if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.ndim != 3 \
                or image.shape[2] != 3:
            desc = (f"{image.dtype} {image.shape}" if isinstance(image, np.ndarray)
                    else type(image).__name__)
            return "bad_frame", f"source delivered {desc}, expected uint8 (H, W, 3) BGR"
        h, w = image.shape[:2]
        if (w, h) != (self.width, self.height):
            return "size_mismatch", (f"frame is {w}x{h} but the calibration is "
                                     f"{self.width}x{self.height}")
        return None


class SourceState(enum.Enum):
    OPENING = "opening"
    STREAMING = "streaming"
    REOPENING = "reopening"
    ENDED = "ended"


class Health:
    """Whether the camera delivers: source state, last error, age of the last frame."""

    def __init__(self, stall_timeout_s: float) -> None:
        self.stall_timeout_ns = round(stall_timeout_s * NS_PER_S)
        self.state = SourceState.OPENING
        self.error = ""
        self.retry_in_s = 0.0
        self.reopens = 0
        self.last_frame_mono_ns: int | None = None
        self._streaming_since_ns = 0

    def streaming(self, now_mono_ns: int) -> None:
        self.state = SourceState.STREAMING
        self._streaming_since_ns = now_mono_ns

    def frame(self, now_mono_ns: int) -> None:
        self.last_frame_mono_ns = now_mono_ns

    def failed(self, error: str, retry_in_s: float) -> None:
        if self.state is SourceState.STREAMING:
            self.reopens += 1
        self.state = SourceState.REOPENING
        self.error = error
        self.retry_in_s = retry_in_s

    def ended(self) -> None:
        self.state = SourceState.ENDED

    def status(self, now_mono_ns: int, rejection: str = "") -> tuple[bool, str]:
        """(healthy, status): healthy only while streaming frames younger than the stall
        timeout that were not rejected; otherwise the status says why."""
        if self.state is SourceState.ENDED:
            return False, "end of stream"
        if self.state is SourceState.REOPENING:
            return False, f"source failed ({self.error}); reopening in {self.retry_in_s:.1f} s"
        if self.state is SourceState.OPENING:
            return False, "opening source"
        since = self.last_frame_mono_ns
        if since is None or since < self._streaming_since_ns:
            since = self._streaming_since_ns
        age_s = (now_mono_ns - since) / NS_PER_S
        if now_mono_ns - since > self.stall_timeout_ns:
            what = "frame" if self.last_frame_mono_ns is not None else "frame yet"
            return False, f"no {what} for {age_s:.1f} s" + (f" ({rejection})" if rejection else "")
        return True, ""


class Backoff:
    """Reopen delays: initial, doubling up to max; reset after a frame arrives."""

    def __init__(self, initial_s: float, max_s: float) -> None:
        self.initial_s = initial_s
        self.max_s = max_s
        self._next = initial_s

    def next_delay(self) -> float:
        delay = self._next
        self._next = min(self._next * 2, self.max_s)
        return delay

    def reset(self) -> None:
        self._next = self.initial_s


def camera_info(cal: Calibration, camera: str, fps: float, source_kind: str, stats: FrameStats,
                skipped_inputs: int, healthy: bool, status: str, reopens: int,
                header: Header) -> CameraInfo:
    """CameraInfo from the calibration and the current counters.

    `read_errors` = unreadable inputs the source skipped + frames rejected + source
    failures; `errors` breaks it down by reason.
    """
    errors = stats.errors.snapshot()
    if skipped_inputs:
        errors["unreadable_input"] = skipped_inputs
    return CameraInfo(
        header=header, camera=camera, width=cal.width, height=cal.height,
        k=tuple(float(v) for v in cal.k.ravel()),
        dist=tuple(float(v) for v in cal.dist.ravel()),
        r=tuple(float(v) for v in cal.r.ravel()),
        t_m=tuple(float(v) for v in cal.t.ravel()),
        fps=fps, source=source_kind,
        frames_published=stats.published, frames_dropped=stats.dropped,
        read_errors=sum(errors.values()), healthy=healthy, status=status,
        frames_captured=stats.captured, frames_decimated=stats.decimated,
        reopens=reopens, errors=errors, depth_published=stats.depth_published,
    )
