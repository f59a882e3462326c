"""Recordings in the project's MCAP layout, read and written with the `mcap` package.

The layout (fixed for every tool): one channel per Zenoh key, topic = the full key
(`aeb/<vehicle>/radar/front/tracks`), message encoding `msgpack`, schema name
`aeb.<MessageType>` with schema encoding `jsonschema` (msgspec's JSON schema of the
type); log_time = the recorder's receive time (ns), publish_time = the message's
`header.stamp_ns`. Channels with other schemas (the Foxglove ones under `/foxglove/`)
are ignored here. The writer is what tests and `aeb eval record-demo` use to produce
such files.
"""

import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import msgspec
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from common.messages import encode

SCHEMA_PREFIX = "aeb."
MESSAGE_ENCODING = "msgpack"


class RecordingError(ValueError):
    """A file that is not a readable MCAP recording; the message says why."""


@dataclass(frozen=True)
class Channel:
    topic: str
    schema: str          # the message type's name, without the "aeb." prefix


@dataclass(frozen=True)
class Message:
    channel: Channel
    log_time_ns: int
    publish_time_ns: int
    data: bytes


def channels(path: Path) -> list[Channel]:
    """The stack's own channels of a recording. Raises RecordingError."""
    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read: {exc.strerror}") from exc
    except Exception as exc:  # the mcap package raises its own and struct errors
        raise RecordingError(f"{path}: not an MCAP file: {exc}") from exc
    if summary is None:
        raise RecordingError(f"{path}: MCAP file without a summary (unfinished recording?)")
    out = []
    for ch in summary.channels.values():
        schema = summary.schemas.get(ch.schema_id)
        if (schema is not None and schema.name.startswith(SCHEMA_PREFIX)
                and ch.message_encoding == MESSAGE_ENCODING):
            out.append(Channel(ch.topic, schema.name[len(SCHEMA_PREFIX):]))
    return sorted(out, key=lambda c: c.topic)


def messages(path: Path, topics: list[str], start_ns: int | None = None,
             end_ns: int | None = None) -> Iterator[Message]:
    """The messages of `topics` in log-time order, logged from `start_ns` (inclusive) to
    `end_ns` (exclusive). Raises RecordingError."""
    try:
        f = open(path, "rb")  # noqa: SIM115 (closed in finally: a generator)
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read: {exc.strerror}") from exc
    try:
        reader = make_reader(f)
        for schema, ch, msg in reader.iter_messages(topics=topics, starting_at=start_ns,
                                                    ending_before=end_ns, log_time_order=True):
            if schema is None or ch.message_encoding != MESSAGE_ENCODING:
                continue
            yield Message(Channel(ch.topic, schema.name[len(SCHEMA_PREFIX):]),
                          msg.log_time, msg.publish_time, msg.data)
    except RecordingError:
        raise
    except Exception as exc:
        raise RecordingError(f"{path}: unreadable MCAP data: {exc}") from exc
    finally:
        f.close()


class RecordingWriter:
    """Writes messages in the layout above. Use as a context manager."""

    def __init__(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self._f: IO[bytes] = open(path, "wb")  # noqa: SIM115 (closed in close())
        self._w = Writer(self._f, compression=CompressionType.ZSTD)
        self._w.start(profile="", library="aeb-eval")
        self._schemas: dict[type[Any], int] = {}
        self._channels: dict[str, int] = {}
        self._seq: dict[str, int] = {}

    def _channel(self, topic: str, msg_type: type[Any]) -> int:
        cid = self._channels.get(topic)
        if cid is not None:
            return cid
        sid = self._schemas.get(msg_type)
        if sid is None:
            schema = json.dumps(msgspec.json.schema(msg_type)).encode()
            sid = self._w.register_schema(f"{SCHEMA_PREFIX}{msg_type.__name__}",
                                          "jsonschema", schema)
            self._schemas[msg_type] = sid
        cid = self._w.register_channel(topic, MESSAGE_ENCODING, sid)
        self._channels[topic] = cid
        return cid

    def write(self, topic: str, msg: msgspec.Struct, log_time_ns: int) -> None:
        header = getattr(msg, "header", None)
        self.write_raw(topic, type(msg), encode(msg), log_time_ns,
                       header.stamp_ns if header is not None else log_time_ns)

    def write_raw(self, topic: str, msg_type: type[Any], payload: bytes, log_time_ns: int,
                  publish_time_ns: int) -> None:
        cid = self._channel(topic, msg_type)
        seq = self._seq.get(topic, 0)
        self._seq[topic] = seq + 1
        self._w.add_message(cid, log_time=log_time_ns, data=payload,
                            publish_time=publish_time_ns, sequence=seq)

    def close(self) -> None:
        self._w.finish()
        self._f.close()

    def __enter__(self) -> "RecordingWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
