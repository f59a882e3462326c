"""A recording of fusion outputs for `aeb ab-report --from`: length-prefixed records,
each a msgpack array [key name, key, receipt wall ns, payload]. Payloads are the bytes
as they were on the bus, so a recording replays through the same decoder."""

import struct
from collections.abc import Iterator
from pathlib import Path
from typing import IO

import msgspec

_LEN = struct.Struct(">I")
_encoder = msgspec.msgpack.Encoder()
_decoder = msgspec.msgpack.Decoder(tuple[str, str, int, bytes])


class RecordingError(ValueError):
    """A recording that is truncated or not one of ours."""


def write_record(out: IO[bytes], spec_name: str, key: str, rx_wall_ns: int,
                 payload: bytes) -> None:
    body = _encoder.encode((spec_name, key, rx_wall_ns, payload))
    out.write(_LEN.pack(len(body)) + body)


def read_records(path: str | Path) -> Iterator[tuple[str, str, int, bytes]]:
    """Every record in order. Raises RecordingError (with the offset) on a damaged file;
    a record cut short at the very end (recording interrupted) ends the iteration."""
    with open(path, "rb") as f:
        offset = 0
        while True:
            head = f.read(_LEN.size)
            if not head:
                return
            if len(head) < _LEN.size:
                return
            (n,) = _LEN.unpack(head)
            body = f.read(n)
            if len(body) < n:
                return
            try:
                yield _decoder.decode(body)
            except msgspec.DecodeError as exc:
                raise RecordingError(f"{path}: bad record at byte {offset}: {exc}") from exc
            offset += _LEN.size + n
