"""Recorded depth for tools that run fusion's checks on a recording (`aeb rerun`,
`aeb eval`): each camera's DepthFrames kept raw by capture stamp, decoded by fusion's
own `decode_depth_frame` when a frame of that stamp is first checked."""

from collections import OrderedDict
from collections.abc import Mapping

import msgspec
import numpy as np

from aeb_radar_camera.common.messages import DecodeError
from aeb_radar_camera.services.fusion.frames import FrameError, decode_depth_frame


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
    rejected payloads by camera. Each DepthFrame is kept with its receive time: asked
    `by_ns`, one received later is not there yet (as live fusion had not received it)."""

    _DECODED_KEPT = 8

    def __init__(self, sizes: Mapping[str, tuple[int, int]], keep: int,
                 counters: dict[str, int]) -> None:
        self.sizes = dict(sizes)
        self.keep = keep
        self.counters = counters
        self.unusable: dict[str, int] = {}
        self._raw: dict[str, OrderedDict[int, tuple[bytes, int]]] = {
            c: OrderedDict() for c in sizes}
        self._decoded: OrderedDict[tuple[str, int], np.ndarray | None] = OrderedDict()

    def add(self, camera: str, payload: bytes, rx_ns: int) -> None:
        """A DepthFrame payload of `camera`, received at `rx_ns`."""
        try:
            stamp = message_head(payload).stamp_ns
        except DecodeError:
            self.count_unusable(camera, "depth_message")
            return
        raw = self._raw[camera]
        raw[stamp] = (payload, rx_ns)
        while len(raw) > self.keep:
            raw.popitem(last=False)

    def at(self, camera: str, stamp_ns: int, by_ns: int | None = None) -> np.ndarray | None:
        """The depth of the frame captured at `stamp_ns` (float32 metres at the frame's
        size), None when none was recorded (received by `by_ns`, when given) or it does
        not decode (counted)."""
        if not self.has(camera, stamp_ns, by_ns):
            return None
        key = (camera, stamp_ns)
        if key in self._decoded:
            return self._decoded[key]
        payload = self._raw[camera][stamp_ns][0]
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

    def has(self, camera: str, stamp_ns: int, by_ns: int | None = None) -> bool:
        """Whether a DepthFrame of `camera` captured at `stamp_ns` was recorded (and
        received by `by_ns`, when given)."""
        raw = self._raw.get(camera)
        kept = raw.get(stamp_ns) if raw is not None else None
        return kept is not None and (by_ns is None or kept[1] <= by_ns)

    def count_unusable(self, camera: str, reason: str) -> None:
        """A depth image of `camera` that could not be used, by reason."""
        self.counters[reason] = self.counters.get(reason, 0) + 1
        self.unusable[camera] = self.unusable.get(camera, 0) + 1
