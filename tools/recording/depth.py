"""Recorded depth for tools that run fusion's checks on a recording (`aeb rerun`,
`aeb eval`): each camera's DepthFrames kept raw by capture stamp, decoded by fusion's
own `decode_depth_frame` when a frame of that stamp is first checked."""

from collections import OrderedDict
from collections.abc import Mapping

import msgspec
import numpy as np

from common.messages import DecodeError
from services.fusion.frames import FrameError, decode_depth_frame


class Head(msgspec.Struct):
    seq: int
    stamp_ns: int


class _Stamped(msgspec.Struct):
    header: Head      # the rest of the message (image bytes) is skipped, not copied


_head_decoder = msgspec.msgpack.Decoder(_Stamped)


def message_head(payload: bytes) -> Head:
    """The sequence number and stamp of a stack message with a header (CompressedFrame,
    DepthFrame), without decoding the rest. Raises DecodeError."""
    try:
        return _head_decoder.decode(payload).header
    except (msgspec.DecodeError, msgspec.ValidationError) as exc:
        raise DecodeError(f"message header: {exc}") from exc


class RecordedDepth:
    """`sizes`: each camera's frame size (width, height), the size depth is brought to;
    `keep`: raw DepthFrames kept per camera (the oldest go first); `counters`: rejected
    payloads by reason (`depth_message`, and decode_depth_frame's reasons); `unusable`:
    rejected payloads by camera."""

    _DECODED_KEPT = 8

    def __init__(self, sizes: Mapping[str, tuple[int, int]], keep: int,
                 counters: dict[str, int]) -> None:
        self.sizes = dict(sizes)
        self.keep = keep
        self.counters = counters
        self.unusable: dict[str, int] = {}
        self._raw: dict[str, OrderedDict[int, bytes]] = {c: OrderedDict() for c in sizes}
        self._decoded: OrderedDict[tuple[str, int], np.ndarray | None] = OrderedDict()

    def add(self, camera: str, payload: bytes) -> None:
        try:
            stamp = message_head(payload).stamp_ns
        except DecodeError:
            self.count_unusable(camera, "depth_message")
            return
        raw = self._raw[camera]
        raw[stamp] = payload
        while len(raw) > self.keep:
            raw.popitem(last=False)

    def at(self, camera: str, stamp_ns: int) -> np.ndarray | None:
        """The depth of the frame captured at `stamp_ns` (float32 metres at the frame's
        size), None when none was recorded or it does not decode (counted)."""
        key = (camera, stamp_ns)
        if key in self._decoded:
            return self._decoded[key]
        raw = self._raw.get(camera)
        payload = raw.get(stamp_ns) if raw is not None else None
        if payload is None:
            return None
        width, height = self.sizes[camera]
        depth: np.ndarray | None
        try:
            depth = decode_depth_frame(payload, width, height)[1]
        except FrameError as exc:
            self.count_unusable(camera, exc.reason)
            depth = None
        self._decoded[key] = depth
        if len(self._decoded) > self._DECODED_KEPT:
            self._decoded.popitem(last=False)
        return depth

    def has(self, camera: str, stamp_ns: int) -> bool:
        """Whether a DepthFrame of `camera` captured at `stamp_ns` was recorded."""
        raw = self._raw.get(camera)
        return raw is not None and stamp_ns in raw

    def count_unusable(self, camera: str, reason: str) -> None:
        """A depth image of `camera` that could not be used, by reason."""
        self.counters[reason] = self.counters.get(reason, 0) + 1
        self.unusable[camera] = self.unusable.get(camera, 0) + 1
