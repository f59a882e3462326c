"""msgpack encoding of messages, with one cached decoder per type."""

from typing import Any, TypeVar

import msgspec

from aeb_radar_camera.common.messages.header import SCHEMA_VERSION

T = TypeVar("T", bound=msgspec.Struct)

_encoder = msgspec.msgpack.Encoder()
_decoders: dict[type[Any], msgspec.msgpack.Decoder[Any]] = {}


class DecodeError(ValueError):
    """A payload that is not a valid message of the expected type and schema version."""


def encode(msg: msgspec.Struct) -> bytes:
    return _encoder.encode(msg)


def decode(payload: bytes | bytearray | memoryview, msg_type: type[T]) -> T:
    """Decode `payload` as `msg_type`.

    Raises DecodeError when the bytes are not valid msgpack, do not match the type, or
    carry another schema version.
    """
    dec = _decoders.get(msg_type)
    if dec is None:
        dec = _decoders[msg_type] = msgspec.msgpack.Decoder(msg_type)
    try:
        msg: T = dec.decode(payload)
    except (msgspec.DecodeError, msgspec.ValidationError) as exc:
        raise DecodeError(f"{msg_type.__name__}: {exc}") from exc
    header = getattr(msg, "header", None)
    if header is not None and header.schema != SCHEMA_VERSION:
        raise DecodeError(
            f"{msg_type.__name__}: schema version {header.schema}, expected {SCHEMA_VERSION}"
        )
    return msg
