"""Fusion's camera frames offline: each camera's FrameFeed as fusion's FrameDecoder holds
it at a radar cycle, for the tools that run fusion's code on recorded frames (`aeb rerun
fusion`, `aeb eval` on recordings).

Fed each camera's frames and depth in the order fusion receives them, a FrameSource
gives the camera's feed at a moment (`feed`): the newest RING_SIZE (fusion's own
constant) of the frames received by then that are not known to be undecodable, with the
counters fusion's decoder keeps. Unlike the live decoder nothing is decoded on arrival:
a frame's pixels are produced when fusion's code first reads its `gray` (a cycle that
gates nothing decodes nothing), by whatever produced the frame - a recorded JPEG through
fusion's `decode_frame` (`add_recorded`), or any other producer of pixels (`add`). A
frame whose pixels cannot be produced raises FrameError to its reader, is counted as
fusion counts an undecodable frame, and is in no ring after that: live fusion never
holds one. A frame's depth is the recorded DepthFrame of its capture stamp
(tools/recording/depth.py).

What the live decoder knows and this cannot: frames it dropped behind a backlog, and a
picture repeated (a frozen camera), which take every frame decoded; `dropped`, `skipped`
and `unchanged_since_ns` keep their defaults. Undecodable frames are known once read.
"""

from collections import OrderedDict, deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from common.messages import DecodeError
from services.fusion.frames import RING_SIZE, DecodedFrame, FrameError, FrameFeed, decode_frame
from tools.recording.depth import RecordedDepth, message_head

# Frames kept per camera (their payloads, undecoded), to build rings from: a ring is
# the newest few received before a moment at most a second or so back.
WINDOW_FRAMES = 64
# Decoded pixels kept, over all cameras: a cycle reads one frame per camera, and the
# next cycles mostly the same ones.
DECODED_KEPT = 8

Pixels = Callable[[], np.ndarray]
"""Produces a frame's grayscale pixels (2-D uint8 at the camera's calibration size).
Raises FrameError (`reason` names the counter)."""


@dataclass(frozen=True, slots=True)
class RecordedJpeg:
    """The pixels of a recorded CompressedFrame, decoded as fusion decodes it."""

    payload: bytes
    rx_ns: int
    width: int
    height: int

    def __call__(self) -> np.ndarray:
        return decode_frame(self.payload, self.rx_ns, self.width, self.height).gray


class SourcedFrame(DecodedFrame):
    """A frame fusion's code sees as decoded: its times at once, its pixels produced
    when `gray` is first read (kept while the source keeps them), its depth the source's
    for its capture stamp. `rx_mono_ns` is when it was received (a recording: the
    recorder's log time), which orders frames for the paper's "newest frame" policy.
    Frames are compared by identity."""

    __slots__ = ("_error", "_pixels", "_produce", "_source")
    _error: FrameError | None
    _pixels: np.ndarray | None
    _produce: Pixels
    _source: "FrameSource"

    def __init__(self, camera: str, seq: int, stamp_ns: int, rx_mono_ns: int,
                 produce: Pixels, source: "FrameSource") -> None:
        for name, value in (("camera", camera), ("seq", seq), ("stamp_ns", stamp_ns),
                            ("rx_mono_ns", rx_mono_ns), ("_produce", produce),
                            ("_source", source), ("_pixels", None), ("_error", None)):
            object.__setattr__(self, name, value)

    __eq__ = object.__eq__
    __hash__ = object.__hash__

    @property
    def gray(self) -> np.ndarray:
        """Raises FrameError (every read, once it failed)."""
        return self._source.pixels_of(self)

    @property
    def depth_m(self) -> np.ndarray | None:
        return self._source.depth.at(self.camera, self.stamp_ns)

    @property
    def undecodable(self) -> bool:
        """Its pixels could not be produced (known once read)."""
        return self._error is not None

    def __repr__(self) -> str:
        return (f"SourcedFrame({self.camera!r}, seq={self.seq}, stamp_ns={self.stamp_ns}, "
                f"rx_mono_ns={self.rx_mono_ns})")


@dataclass
class _Camera:
    """One camera's frames and the counts fusion's decoder keeps of them."""

    width: int
    height: int
    frames: deque[SourcedFrame] = field(default_factory=lambda: deque(maxlen=WINDOW_FRAMES))
    received: int = 0
    undecodable: int = 0
    errors_by_reason: dict[str, int] = field(default_factory=dict)
    # Messages without a readable header (never frames): receive time and error.
    unreadable: deque[tuple[int, str]] = field(
        default_factory=lambda: deque(maxlen=WINDOW_FRAMES))
    depth_received: int = 0
    depth_rx: deque[int] = field(default_factory=lambda: deque(maxlen=2 * WINDOW_FRAMES))

    def count_undecodable(self, reason: str) -> None:
        self.undecodable += 1
        self.errors_by_reason[reason] = self.errors_by_reason.get(reason, 0) + 1


class FrameSource:
    """`sizes`: each camera's frame size (width, height) from its calibration; `counters`:
    unusable depth by reason (`depth_message` and decode_depth_frame's reasons)."""

    def __init__(self, sizes: Mapping[str, tuple[int, int]],
                 counters: dict[str, int] | None = None) -> None:
        self._cameras = {name: _Camera(w, h) for name, (w, h) in sizes.items()}
        self.depth = RecordedDepth(sizes, 2 * WINDOW_FRAMES, {} if counters is None
                                   else counters)
        self._decoded: OrderedDict[int, SourcedFrame] = OrderedDict()
        self.decoded = 0          # pixels produced (a frame again after it was let go)
        self.decode_failed = 0    # frames whose pixels could not be produced

    def add_recorded(self, camera: str, payload: bytes, rx_ns: int) -> SourcedFrame:
        """A recorded CompressedFrame payload of `camera`, received at `rx_ns`. Raises
        DecodeError when its header is unreadable (counted as an undecodable frame)."""
        cam = self._cameras[camera]
        try:
            head = message_head(payload)
        except DecodeError:
            cam.received += 1
            cam.count_undecodable("message")
            cam.unreadable.append((rx_ns, _decode_error(payload)))
            raise
        return self.add(camera, head.seq, head.stamp_ns, rx_ns,
                        RecordedJpeg(payload, rx_ns, cam.width, cam.height))

    def add(self, camera: str, seq: int, stamp_ns: int, rx_ns: int,
            produce: Pixels) -> SourcedFrame:
        """A frame of `camera` captured at `stamp_ns`, received at `rx_ns` (frames are
        added in the order received), its pixels from `produce` when first read."""
        cam = self._cameras[camera]
        frame = SourcedFrame(camera, seq, stamp_ns, rx_ns, produce, self)
        cam.frames.append(frame)
        cam.received += 1
        return frame

    def add_depth(self, camera: str, payload: bytes, rx_ns: int) -> None:
        """A recorded DepthFrame payload of `camera`, paired with the frame of its capture
        stamp when that frame's depth is read."""
        cam = self._cameras[camera]
        cam.depth_received += 1
        cam.depth_rx.append(rx_ns)
        self.depth.add(camera, payload)

    def window(self, camera: str) -> tuple[SourcedFrame, ...]:
        """The camera's recent frames, in the order received (the last WINDOW_FRAMES)."""
        return tuple(self._cameras[camera].frames)

    def received_by(self, camera: str, at_ns: int) -> list[SourcedFrame]:
        """The camera's recent frames received by `at_ns`."""
        return [f for f in self._cameras[camera].frames if f.rx_mono_ns <= at_ns]

    @staticmethod
    def ring(frames: Iterable[SourcedFrame]) -> tuple[SourcedFrame, ...]:
        """Fusion's ring of `frames` (in the order received): the newest RING_SIZE of
        those not known to be undecodable."""
        return tuple(f for f in frames if not f.undecodable)[-RING_SIZE:]

    def feed(self, camera: str, at_ns: int,
             ring: Iterable[SourcedFrame] | None = None) -> FrameFeed:
        """The camera's FrameFeed at `at_ns`: `ring` (default: fusion's ring of the frames
        received by then), with the decoder's counters of what was received by then."""
        cam = self._cameras[camera]
        frames = self.ring(self.received_by(camera, at_ns)) if ring is None else tuple(ring)
        later = (sum(1 for f in cam.frames if f.rx_mono_ns > at_ns)
                 + sum(1 for rx, _ in cam.unreadable if rx > at_ns))
        error, error_rx = _last_error(cam, at_ns)
        return FrameFeed(frames, cam.received - later, cam.undecodable,
                         last_error=error, last_error_rx_mono_ns=error_rx,
                         corrupt=cam.errors_by_reason.get("corrupt", 0),
                         depth_received=cam.depth_received - sum(
                             1 for rx in cam.depth_rx if rx > at_ns),
                         depth_undecodable=self.depth.unusable.get(camera, 0))

    def pixels_of(self, frame: SourcedFrame) -> np.ndarray:
        """A frame's pixels: produced on the first read (counted, and kept among the
        last DECODED_KEPT read), the same ones after that. Raises FrameError (the frame
        is then undecodable: counted once, and in no ring after that)."""
        pixels: np.ndarray | None = frame._pixels
        if pixels is not None:
            self._decoded.move_to_end(id(frame))
            return pixels
        if frame._error is not None:
            raise frame._error
        try:
            pixels = frame._produce()
        except FrameError as exc:
            object.__setattr__(frame, "_error", exc)
            self.decode_failed += 1
            self._cameras[frame.camera].count_undecodable(exc.reason)
            raise
        self.decoded += 1
        object.__setattr__(frame, "_pixels", pixels)
        self._decoded[id(frame)] = frame
        if len(self._decoded) > DECODED_KEPT:
            _, oldest = self._decoded.popitem(last=False)
            object.__setattr__(oldest, "_pixels", None)
        return pixels


def _decode_error(payload: bytes) -> str:
    """What fusion's decode_frame says of a payload without a readable header."""
    try:
        decode_frame(payload, 0, 0, 0)
    except FrameError as exc:
        return str(exc)
    return ""


def _last_error(cam: _Camera, at_ns: int) -> tuple[str, int | None]:
    """The newest frame received by `at_ns` known to be undecodable: its error and
    receive time (as the decoder's last error), else ("", None)."""
    known = [(f.rx_mono_ns, str(f._error)) for f in cam.frames
             if f._error is not None and f.rx_mono_ns <= at_ns]
    known += [(rx, error) for rx, error in cam.unreadable if rx <= at_ns]
    if not known:
        return "", None
    rx, error = max(known)
    return error, rx
