"""Decode and encode ARS408 frames from the signal table.

- `decode(spec, data)`: one frame to its record (raises RadarFrameError): the status, radar
  state and version frames, one at a time.
- `decode_frame(arb_id, data)`: classify the ID, then decode (raises RadarFrameError).
- `encode(record, sensor_id)`: a record to a `RadarFrame` (raises EncodeError).
- `decode_columns(spec, datas)`: the list frames of a cycle (general, quality, extended),
  all of one message at once, to one numpy row per signal with a per-frame validity mask.
"""

import math
from collections.abc import Sequence
from typing import Any, NamedTuple, cast

import numpy as np
import numpy.typing as npt

from aeb_radar_camera.services.radar.ars408.table import (
    BY_RECORD,
    MAX_SENSORS,
    SENSOR_ID_STRIDE,
    MessageSpec,
    Signal,
    classify,
)


class RadarFrame(NamedTuple):
    """A classic CAN frame with an 11-bit ID, to or from the radar (as encoded or to be
    written; a frame as received, with its times and flags, is common's CanFrame)."""

    arb_id: int
    data: bytes


class RadarFrameError(ValueError):
    """A radar frame that cannot be used; `reason` is the short counter key (e.g. ``wrong_dlc``)."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason


class EncodeError(ValueError):
    """A physical value that the signal cannot represent."""


def _word(data: bytes | bytearray) -> int:
    """The frame as a 64-bit big-endian word, short frames padded with zero bytes."""
    return int.from_bytes(data, "big") << (8 * (8 - len(data)))


def check_dlc(spec: MessageSpec, data: bytes | bytearray) -> None:
    """Raises RadarFrameError('wrong_dlc') when `data` is shorter than the message needs."""
    if len(data) < spec.dlc or len(data) > 8:
        raise RadarFrameError("wrong_dlc",
                              f"{spec.dbc_name} has {len(data)} bytes, expects {spec.dlc}")


# raw * scale + offset is inexact in binary (1523 * 0.2 - 204.6 = 100.00000000000003):
# a bound is met within this much.
_EPS = 1e-6


def _within(valid: tuple[float, float], value: float) -> bool:
    return valid[0] - _EPS <= value <= valid[1] + _EPS


def _value(sig: Signal, raw: int) -> float | int:
    if sig.is_integer:
        return raw
    return raw * sig.scale + sig.offset


def decode(spec: MessageSpec, data: bytes | bytearray) -> Any:
    """Decode one frame's payload as `spec`'s record.

    Raises RadarFrameError with reason ``wrong_dlc`` or ``out_of_range`` (naming the signal).
    """
    check_dlc(spec, data)
    word = _word(data)
    values = []
    for sig in spec.signals:
        value = _value(sig, (word >> sig.shift) & sig.mask)
        if sig.valid is not None and not _within(sig.valid, value):
            lo, hi = sig.valid
            raise RadarFrameError("out_of_range",
                                  f"{sig.dbc_name}={value:g} outside {lo:g}..{hi:g}")
        values.append(value)
    return spec.record(*values)


def decode_frame(arb_id: int, data: bytes | bytearray) -> tuple[MessageSpec, int, Any]:
    """(spec, sensor ID, record) of an ARS408 frame.

    Raises RadarFrameError with reason ``unknown_id``, ``wrong_dlc`` or ``out_of_range``.
    """
    found = classify(arb_id)
    if found is None:
        raise RadarFrameError("unknown_id", f"0x{arb_id:03X} is not an ARS408 message")
    spec, sensor_id = found
    return spec, sensor_id, decode(spec, data)


def encode(record: NamedTuple, sensor_id: int = 0, validate: bool = True) -> RadarFrame:
    """The frame carrying `record` from/to radar `sensor_id` (ID + 0x10 * sensor_id).

    Raises EncodeError when a value is not representable: not finite, out of the raw
    range, or (with `validate`) outside the signal's valid range, which the decoder would
    reject; pass
    ``validate=False`` to build such a frame on purpose (fault injection). Raises
    ValueError for a sensor ID outside 0..7, KeyError for a type that is not an ARS408
    record.
    """
    spec = BY_RECORD[type(record)]
    if not 0 <= sensor_id < MAX_SENSORS:
        raise ValueError(f"sensor_id {sensor_id} outside 0..{MAX_SENSORS - 1}")
    word = 0
    for sig, value in zip(spec.signals, record, strict=True):
        scaled = (value - sig.offset) / sig.scale
        if not math.isfinite(scaled):   # round() would raise ValueError / OverflowError
            raise EncodeError(f"{sig.dbc_name}={value} is outside the signal's raw range")
        raw = round(scaled)
        if not 0 <= raw <= sig.mask:
            raise EncodeError(f"{sig.dbc_name}={value} is outside the signal's raw range")
        if validate and sig.valid is not None and not _within(sig.valid, _value(sig, raw)):
            raise EncodeError(f"{sig.dbc_name}={value} is outside {sig.valid}")
        word |= raw << sig.shift
    data = word.to_bytes(8, "big")[: spec.dlc]
    return RadarFrame(spec.base_id + SENSOR_ID_STRIDE * sensor_id, data)


BoolArray = npt.NDArray[np.bool_]


class Columns:
    """Many frames of one message decoded: one row per signal, plus which frames are valid.

    `raw` (int64) and `phys` (float64) are (signals, frames) matrices in signal order (a
    signal is a contiguous row; `phys` is computed when first asked for); `values` maps
    attribute names to those rows (integers from `raw`). `valid` marks the frames whose
    every signal is within its valid range (`all_valid`: all of them); `rejected` maps
    ``out_of_range:<signal>`` to the number of frames it invalidated.
    """

    __slots__ = ("_layout", "_phys", "_valid", "all_valid", "raw", "rejected")

    def __init__(self, layout: "_Layout", raw: npt.NDArray[np.int64], valid: BoolArray | None,
                 rejected: dict[str, int]) -> None:
        """`valid` None: every frame is."""
        self._layout = layout
        self.raw = raw
        self._valid = valid
        self.all_valid = valid is None
        self.rejected = rejected
        self._phys: npt.NDArray[np.float64] | None = None

    @property
    def phys(self) -> npt.NDArray[np.float64]:
        if self._phys is None:
            self._phys = self.raw * self._layout.scales + self._layout.offsets
        return self._phys

    @property
    def valid(self) -> BoolArray:
        if self._valid is None:
            return np.ones(self.raw.shape[1], dtype=np.bool_)
        return self._valid

    @property
    def values(self) -> dict[str, npt.NDArray[Any]]:
        """Every signal by attribute name."""
        phys = self.phys
        return {attr: self.raw[k] if is_int else phys[k]
                for k, (attr, is_int) in enumerate(self._layout.attrs)}


def words(datas: Sequence[bytes | bytearray], spec_dlc: int = 8) -> npt.NDArray[np.int64]:
    """Frames of one message (DLC-checked: spec_dlc..8 bytes) as 64-bit words
    (big-endian payload), zero padded.

    Signed storage is harmless: every signal is extracted by shift and mask."""
    n = len(datas)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    # Frames of the message's DLC (0x60C has 7 bytes, 0x702 5) joined by the padding
    # each needs: every frame ends up 8 bytes long, unless one was longer.
    pad = bytes(8 - spec_dlc)
    buf = pad.join(datas) + pad
    if len(buf) != 8 * n:
        buf = b"".join(bytes(d).ljust(8, b"\0") for d in datas)
    return np.frombuffer(buf, dtype=np.int64).byteswap()     # big-endian payloads


class _Layout(NamedTuple):
    """A message's signals as column vectors, so that every signal decodes in one matrix
    operation. `checked` lists the rows that have a valid range, `lo` and `span` that
    range in raw units: raw - lo from 0 to span (the same frames as the range on
    raw * scale + offset, found by trying every raw value); `lo` None when every range
    starts at raw 0."""

    attrs: tuple[tuple[str, bool], ...]
    shifts: npt.NDArray[np.int64]
    masks: npt.NDArray[np.int64]
    scales: npt.NDArray[np.float64]
    offsets: npt.NDArray[np.float64]
    checked: npt.NDArray[np.intp]
    lo: npt.NDArray[np.int64] | None
    span: npt.NDArray[np.uint64]


def _raw_range(sig: Signal) -> tuple[int, int]:
    """The raw values whose physical value is valid, as (first, last): an interval,
    since raw * scale + offset grows with raw."""
    assert sig.valid is not None and sig.scale > 0
    raw = np.arange(sig.mask + 1, dtype=np.int64)
    phys = raw * np.float64(sig.scale) + np.float64(sig.offset)
    ok = np.flatnonzero((phys >= sig.valid[0] - _EPS) & (phys <= sig.valid[1] + _EPS))
    assert len(ok) and ok[-1] - ok[0] + 1 == len(ok), sig.dbc_name
    return int(ok[0]), int(ok[-1])


_layouts: dict[str, _Layout] = {}


def _layout(spec: MessageSpec) -> _Layout:
    found = _layouts.get(spec.dbc_name)
    if found is None:
        sigs = spec.signals
        checked = [k for k, s in enumerate(sigs) if s.valid is not None]
        ranges = [_raw_range(sigs[k]) for k in checked]
        found = _layouts[spec.dbc_name] = _Layout(
            attrs=tuple((s.attr, s.is_integer) for s in sigs),
            shifts=np.array([[s.shift] for s in sigs], dtype=np.int64),
            masks=np.array([[s.mask] for s in sigs], dtype=np.int64),
            scales=np.array([[s.scale] for s in sigs]),
            offsets=np.array([[s.offset] for s in sigs]),
            checked=np.array(checked, dtype=np.intp),
            lo=np.array([[lo] for lo, _ in ranges], dtype=np.int64)
            if any(lo for lo, _ in ranges) else None,
            span=np.array([[hi - lo] for lo, hi in ranges], dtype=np.uint64),
        )
    return found


def decode_columns(spec: MessageSpec, datas: Sequence[bytes | bytearray]) -> Columns:
    """`decode` of many DLC-checked payloads of one message at once: every signal of
    every frame as one (signals, n) matrix operation."""
    lay = _layout(spec)
    raw = (words(datas, spec.dlc) >> lay.shifts) & lay.masks
    if not len(lay.checked):
        return Columns(lay, raw, None, {})
    checked = raw.take(lay.checked, axis=0)
    if lay.lo is not None:
        checked = checked - lay.lo
    # Below lo, raw - lo wraps to a huge unsigned value: one comparison tests both bounds.
    ok = checked.view(np.uint64) <= lay.span
    if np.count_nonzero(ok) == ok.size:
        return Columns(lay, raw, None, {})
    valid = cast(BoolArray, ok.all(axis=0))
    rejected: dict[str, int] = {}
    bad_rows = ~valid
    for k, row in enumerate(lay.checked.tolist()):
        bad = int(np.count_nonzero(bad_rows & ~ok[k]))
        if bad:
            rejected[f"out_of_range:{spec.signals[row].dbc_name}"] = bad
        # A frame counts once, under its first bad signal.
        bad_rows &= ok[k]
    return Columns(lay, raw, valid, rejected)
