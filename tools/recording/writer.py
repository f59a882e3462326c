"""Writing recordings: MCAP files with chunks, index and summary (the `mcap` package's
own), split by size or duration, with per-topic counts.

A file is readable at every moment after its first chunk: chunks are written as they
fill (1 MiB, or `flush_s` of data, whichever comes first), and `close()` writes the
summary and index. A process that is killed loses at most the chunk in progress; one
stopped by a signal closes its file (tools/recording/record.py).
"""

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

import msgspec
from mcap.writer import CompressionType, Writer

from aeb_radar_camera.common.messages import encode
from aeb_radar_camera.tools.recording.format import METADATA_NAME, ChannelType, stack_channel

CHUNK_BYTES = 1 << 20
COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
               "none": CompressionType.NONE}


@dataclass
class TopicCount:
    messages: int = 0
    bytes: int = 0


@dataclass
class WriterStats:
    files: list[Path] = field(default_factory=list)
    topics: dict[str, TopicCount] = field(default_factory=dict)

    @property
    def messages(self) -> int:
        return sum(t.messages for t in self.topics.values())

    @property
    def bytes_on_disk(self) -> int:
        return sum(p.stat().st_size for p in self.files if p.exists())


class RecordingWriter:
    """Writes messages into `path`, or with splitting into `<stem>_0000.mcap`,
    `<stem>_0001.mcap`, ... (a new file once `split_bytes` were written into the current
    one or its messages span `split_s`). Every file carries its own schemas, channels and
    the `metadata`, so that each opens on its own. `flush_s`: the chunk in progress goes to
    disk at least this often (None: only when full, for files that must be the same
    bytes for the same messages). `exclusive`: a file that exists already is never
    replaced (FileExistsError instead).

    Not thread-safe: one writer thread. Raises OSError when a file cannot be written.
    """

    def __init__(self, path: str | Path, split_bytes: int | None = None,
                 split_s: float | None = None, compression: str = "zstd",
                 metadata: dict[str, str] | None = None, flush_s: float | None = 2.0,
                 chunk_bytes: int = CHUNK_BYTES, exclusive: bool = False) -> None:
        if compression not in COMPRESSION:
            raise ValueError(f"compression {compression!r}: one of {sorted(COMPRESSION)}")
        self.path = Path(path)
        self.split = split_bytes is not None or split_s is not None
        self.split_bytes = split_bytes
        self.split_ns = None if split_s is None else round(split_s * 1e9)
        self.compression = COMPRESSION[compression]
        self.metadata = dict(metadata or {})
        self.chunk_bytes = chunk_bytes
        self.flush_s = flush_s
        self.exclusive = exclusive
        self.stats = WriterStats()
        self._file: IO[bytes] | None = None
        self._writer: Writer | None = None
        self._schemas: dict[ChannelType, int] = {}
        self._channels: dict[str, int] = {}
        self._file_bytes = 0
        self._file_start_ns: int | None = None
        self._last_flush = time.monotonic()

    def _next_path(self) -> Path:
        if not self.split:
            return self.path
        stem = self.path.name.removesuffix(".mcap")
        return self.path.with_name(f"{stem}_{len(self.stats.files):04d}.mcap")

    def _open(self, log_time_ns: int) -> Writer:
        path = self._next_path()
        path.parent.mkdir(parents=True, exist_ok=True)
        mode = "xb" if self.exclusive else "wb"
        self._file = open(path, mode)  # noqa: SIM115 (closed in _close_file)
        writer = Writer(self._file, chunk_size=self.chunk_bytes, compression=self.compression)
        writer.start(profile="", library="aeb-recorder")
        if self.metadata:
            writer.add_metadata(METADATA_NAME, self.metadata)
        self._writer = writer
        self._schemas.clear()
        self._channels.clear()
        self._file_bytes = 0
        self._file_start_ns = log_time_ns
        self.stats.files.append(path)
        return writer

    def _close_file(self) -> None:
        if self._writer is not None:
            self._writer.finish()
            self._writer = None
        if self._file is not None:
            self._file.close()
            self._file = None

    def _channel(self, writer: Writer, topic: str, kind: ChannelType) -> int:
        channel_id = self._channels.get(topic)
        if channel_id is None:
            schema_id = 0
            if kind.schema_name:
                schema_id = self._schemas.get(kind, 0)
                if not schema_id:
                    schema_id = self._schemas[kind] = writer.register_schema(
                        kind.schema_name, kind.schema_encoding, kind.schema_data)
            channel_id = self._channels[topic] = writer.register_channel(
                topic, kind.message_encoding, schema_id)
        return channel_id

    def write(self, topic: str, kind: ChannelType, payload: bytes, log_time_ns: int,
              publish_time_ns: int, sequence: int = 0) -> None:
        writer = self._writer
        if writer is not None and self.split and (
                (self.split_bytes is not None and self._file_bytes >= self.split_bytes)
                or (self.split_ns is not None and self._file_start_ns is not None
                    and log_time_ns - self._file_start_ns >= self.split_ns)):
            self._close_file()
            writer = None
        if writer is None:
            writer = self._open(log_time_ns)
        channel_id = self._channel(writer, topic, kind)
        writer.add_message(channel_id, log_time_ns, payload, publish_time_ns,
                           sequence & 0xFFFFFFFF)
        self._file_bytes += len(payload)
        count = self.stats.topics.get(topic)
        if count is None:
            count = self.stats.topics[topic] = TopicCount()
        count.messages += 1
        count.bytes += len(payload)
        if self.flush_s is not None and time.monotonic() - self._last_flush >= self.flush_s:
            self.flush()

    def write_message(self, topic: str, msg: msgspec.Struct, log_time_ns: int) -> None:
        """A stack message, encoded as on the bus; its publish time and sequence from its
        header (the log time and 0 without one)."""
        header = getattr(msg, "header", None)
        self.write(topic, stack_channel(type(msg)), encode(msg), log_time_ns,
                   header.stamp_ns if header is not None else log_time_ns,
                   header.seq if header is not None else 0)

    def flush(self) -> None:
        """The chunk in progress to disk (the file stays open and readable up to here)."""
        self._last_flush = time.monotonic()
        if self._writer is not None and self._file is not None:
            self._writer.flush()

    def close(self) -> WriterStats:
        """Summary and index written, files closed. Safe to call twice."""
        self._close_file()
        return self.stats

    def __enter__(self) -> "RecordingWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
