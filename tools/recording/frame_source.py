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
(tools/recording/depth.py) if it was received by the moment of the camera's last feed
(live fusion pairs a depth with its frame only once it has arrived), unless the feed
was told whether the live instance had it (`depth_pins`: what its recorded output says);
or it comes from a producer given with the frame (`add`), also when first read (a
simulator renders it on demand).

What the live decoder knows and this cannot: frames it dropped behind a backlog, and a
picture repeated (a frozen camera), which take every frame decoded; the feed's `dropped`
and `unchanged_since_ns` keep their defaults. Undecodable frames (and depth) are known
once read.
"""

from bisect import bisect_right
from collections import OrderedDict, deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from itertools import islice
from typing import Any

import numpy as np

from aeb_radar_camera.common.messages import DecodeError
from aeb_radar_camera.services.fusion.frames import (
    RING_SIZE,
    DecodedFrame,
    FrameError,
    FrameFeed,
    decode_frame,
)
from aeb_radar_camera.tools.recording.depth import RecordedDepth, message_head

# Frames kept per camera (their payloads, undecoded), to build rings from: a ring is
# the newest few received before a moment at most a second or so back.
WINDOW_FRAMES = 64
# Decoded pixels kept, over all cameras: a cycle reads one frame per camera, and the
# next cycles mostly the same ones.
DECODED_KEPT = 8

Pixels = Callable[[], np.ndarray]
"""Produces a frame's grayscale pixels (2-D uint8 at the camera's calibration size).
Raises FrameError (`reason` names the counter)."""

Depth = Callable[[], np.ndarray]
"""Produces a frame's depth (float32 metres at the frame's size, 0 = no return). Raises
FrameError (`reason` names the counter: the frame then has no depth)."""


@dataclass(slots=True)
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

    __slots__ = ("_depth", "_error", "_pixels", "_produce", "_produce_depth", "_source")
    _error: FrameError | None
    _pixels: np.ndarray | None
    _produce: Pixels
    _produce_depth: Depth | None
    _depth: np.ndarray | FrameError | None
    _source: "FrameSource"

    def __init__(self, camera: str, seq: int, stamp_ns: int, rx_mono_ns: int,
                 produce: Pixels, source: "FrameSource",
                 produce_depth: Depth | None = None) -> None:
        init = object.__setattr__      # frozen to fusion's code, not to its source
        init(self, "camera", camera)
        init(self, "seq", seq)
        init(self, "stamp_ns", stamp_ns)
        init(self, "rx_mono_ns", rx_mono_ns)
        init(self, "_produce", produce)
        init(self, "_source", source)
        init(self, "_pixels", None)
        init(self, "_error", None)
        init(self, "_produce_depth", produce_depth)
        init(self, "_depth", None)

    __eq__ = object.__eq__
    __hash__ = object.__hash__

    @property
    def gray(self) -> np.ndarray:
        """Raises FrameError (every read, once it failed)."""
        return self._source.pixels_of(self)

    @property
    def depth_m(self) -> np.ndarray | None:
        if self._produce_depth is not None:
            return self._source.produced_depth(self)
        return self._source.depth_of(self)

    @property
    def undecodable(self) -> bool:
        """Its pixels could not be produced (known once read)."""
        return self._error is not None

    def __repr__(self) -> str:
        return (f"SourcedFrame({self.camera!r}, seq={self.seq}, stamp_ns={self.stamp_ns}, "
                f"rx_mono_ns={self.rx_mono_ns})")


def _recent() -> deque[Any]:
    return deque(maxlen=2 * WINDOW_FRAMES)


@dataclass
class _Camera:
    """One camera's frames and the counts fusion's decoder keeps of them. Payloads come
    in the order received, so receive times only grow."""

    width: int
    height: int
    frames: deque[SourcedFrame] = field(default_factory=lambda: deque(maxlen=WINDOW_FRAMES))
    received: int = 0
    rx: deque[int] = field(default_factory=_recent)       # of the last payloads
    undecodable: int = 0
    errors_by_reason: dict[str, int] = field(default_factory=dict)
    errors: deque[tuple[int, str]] = field(default_factory=_recent)  # receive time, error
    depth_received: int = 0
    depth_rx: deque[int] = field(default_factory=_recent)

    def count_received(self, rx_ns: int) -> None:
        self.received += 1
        self.rx.append(rx_ns)

    def count_undecodable(self, rx_ns: int, error: FrameError) -> None:
        self.undecodable += 1
        self.errors_by_reason[error.reason] = self.errors_by_reason.get(error.reason, 0) + 1
        self.errors.append((rx_ns, str(error)))


class FrameSource:
    """`sizes`: each camera's frame size (width, height) from its calibration; `counters`:
    unusable depth by reason (`depth_message` and decode_depth_frame's reasons)."""

    def __init__(self, sizes: Mapping[str, tuple[int, int]],
                 counters: dict[str, int] | None = None) -> None:
        self._cameras = {name: _Camera(w, h) for name, (w, h) in sizes.items()}
        self.depth = RecordedDepth(sizes, 2 * WINDOW_FRAMES, {} if counters is None
                                   else counters)
        self._decoded: OrderedDict[int, SourcedFrame] = OrderedDict()
        self._depth_kept: OrderedDict[int, SourcedFrame] = OrderedDict()
        # per camera: the moment of its last feed, and its depth pins (capture stamp ->
        # whether the frame had its depth)
        self._as_of: dict[str, int] = {}
        self._pins: dict[str, Mapping[int, bool]] = {}
        self.decoded = 0          # pixels produced (a frame again after it was let go)
        self.decode_failed = 0    # frames whose pixels could not be produced
        self.depth_produced = 0   # depth produced by a frame's own producer

    def add_recorded(self, camera: str, payload: bytes, rx_ns: int) -> SourcedFrame:
        """A recorded CompressedFrame payload of `camera`, received at `rx_ns`. Raises
        DecodeError when its header is unreadable (counted as an undecodable frame)."""
        cam = self._cameras[camera]
        try:
            head = message_head(payload)
        except DecodeError:
            cam.count_received(rx_ns)
            cam.count_undecodable(rx_ns, _decode_error(payload))
            raise
        return self.add(camera, head.seq, head.stamp_ns, rx_ns,
                        RecordedJpeg(payload, rx_ns, cam.width, cam.height))

    def add(self, camera: str, seq: int, stamp_ns: int, rx_ns: int,
            produce: Pixels, depth: Depth | None = None) -> SourcedFrame:
        """A frame of `camera` captured at `stamp_ns`, received at `rx_ns` (frames are
        added in the order received), its pixels from `produce` when first read; with
        `depth`, its depth (received with it) from that producer when first read."""
        cam = self._cameras[camera]
        frame = SourcedFrame(camera, seq, stamp_ns, rx_ns, produce, self, depth)
        cam.frames.append(frame)
        cam.count_received(rx_ns)
        if depth is not None:
            cam.depth_received += 1
            cam.depth_rx.append(rx_ns)
        return frame

    def add_depth(self, camera: str, payload: bytes, rx_ns: int) -> None:
        """A recorded DepthFrame payload of `camera` received at `rx_ns`, paired with the
        frame of its capture stamp when that frame's depth is read."""
        cam = self._cameras[camera]
        cam.depth_received += 1
        cam.depth_rx.append(rx_ns)
        self.depth.add(camera, payload, rx_ns)

    def has_depth(self, camera: str, stamp_ns: int) -> bool:
        """Whether the frame of `camera` captured at `stamp_ns` has a DepthFrame (usable
        or not) as of the camera's last feed: pinned, or added (received by then) and
        still kept."""
        pinned = self._pins.get(camera, {}).get(stamp_ns)
        if pinned is not None:
            return pinned and self.depth.has(camera, stamp_ns)
        return self.depth.has(camera, stamp_ns, self._as_of.get(camera))

    def depth_of(self, frame: SourcedFrame) -> np.ndarray | None:
        """The frame's depth as of its camera's last feed (None: none then, or unusable)."""
        if not self.has_depth(frame.camera, frame.stamp_ns):
            return None
        return self.depth.at(frame.camera, frame.stamp_ns)

    def window(self, camera: str) -> tuple[SourcedFrame, ...]:
        """The camera's recent frames, in the order received (the last WINDOW_FRAMES)."""
        return tuple(self._cameras[camera].frames)

    def received_by(self, camera: str, at_ns: int) -> list[SourcedFrame]:
        """The camera's recent frames received by `at_ns`."""
        frames = self._cameras[camera].frames
        return list(islice(frames, bisect_right(frames, at_ns, key=_rx)))

    @staticmethod
    def ring(frames: Iterable[SourcedFrame]) -> tuple[SourcedFrame, ...]:
        """Fusion's ring of `frames` (in the order received): the newest RING_SIZE of
        those not known to be undecodable."""
        newest = list(islice((f for f in reversed(list(frames)) if f._error is None),
                             RING_SIZE))
        return tuple(reversed(newest))

    def feed(self, camera: str, at_ns: int, ring: Iterable[SourcedFrame] | None = None,
             depth_pins: Mapping[int, bool] | None = None) -> FrameFeed:
        """The camera's FrameFeed at `at_ns`: `ring` (default: fusion's ring of the frames
        received by then), with the decoder's counters of what was received by then. Its
        frames' depth, until the camera's next feed: the depth received by `at_ns`, except
        for the frames in `depth_pins` (capture stamp -> whether the frame had depth)."""
        cam = self._cameras[camera]
        self._as_of[camera] = at_ns
        self._pins[camera] = depth_pins or {}
        frames = self.ring(self.received_by(camera, at_ns)) if ring is None else tuple(ring)
        error_rx, error = max(((rx, e) for rx, e in cam.errors if rx <= at_ns),
                              default=(None, ""))
        return FrameFeed(frames, received=cam.received - _later(cam.rx, at_ns),
                         undecodable=cam.undecodable,
                         last_error=error, last_error_rx_mono_ns=error_rx,
                         corrupt=cam.errors_by_reason.get("corrupt", 0),
                         depth_received=cam.depth_received - _later(cam.depth_rx, at_ns),
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
            self._cameras[frame.camera].count_undecodable(frame.rx_mono_ns, exc)
            raise
        self.decoded += 1
        _keep(self._decoded, frame, "_pixels", pixels)
        return pixels

    def produced_depth(self, frame: SourcedFrame) -> np.ndarray | None:
        """A frame's depth from its own producer: produced on the first read (kept among
        the last DECODED_KEPT read), the same after that; None once it failed (counted
        once, as fusion counts an undecodable DepthFrame)."""
        assert frame._produce_depth is not None
        kept = frame._depth
        if isinstance(kept, FrameError):
            return None
        if kept is not None:
            self._depth_kept.move_to_end(id(frame))
            return kept
        try:
            depth = frame._produce_depth()
        except FrameError as exc:
            object.__setattr__(frame, "_depth", exc)
            self.depth.count_unusable(frame.camera, exc.reason)
            return None
        self.depth_produced += 1
        _keep(self._depth_kept, frame, "_depth", depth)
        return depth


def _keep(kept: OrderedDict[int, SourcedFrame], frame: SourcedFrame, slot: str,
          value: np.ndarray) -> None:
    """`value` in the frame's `slot`, the newest of the last DECODED_KEPT kept there; the
    oldest beyond those let go (produced again when read again)."""
    object.__setattr__(frame, slot, value)
    kept[id(frame)] = frame
    if len(kept) > DECODED_KEPT:
        _, oldest = kept.popitem(last=False)
        object.__setattr__(oldest, slot, None)


def _rx(frame: SourcedFrame) -> int:
    return frame.rx_mono_ns


def _later(rx: deque[int], at_ns: int) -> int:
    """How many of these receive times (in the order received) are after `at_ns`."""
    return len(rx) - bisect_right(rx, at_ns)


def _decode_error(payload: bytes) -> FrameError:
    """What fusion's decode_frame says of a payload without a readable header."""
    try:
        decode_frame(payload, 0, 0, 0)
    except FrameError as exc:
        if exc.reason == "message":
            return exc
    return FrameError("message", "message header unreadable")
