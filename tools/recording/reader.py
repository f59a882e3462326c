"""Reading recordings: one MCAP file, the files of a split recording, or a folder of
them, as one stream of records in log-time order.

A file whose recorder was killed (no summary: the chunks written so far, then nothing)
is read up to its last complete record; `Recording.truncated` names such files.
"""

import heapq
import logging
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.reader import NonSeekingReader, make_reader
from mcap.writer import MCAP0_MAGIC

from aeb_radar_camera.common.messages import DecodeError, decode
from aeb_radar_camera.tools.recording.format import (
    DERIVED_PREFIX,
    MESSAGE_ENCODING,
    METADATA_NAME,
    TopicInfo,
    parse_topic,
)

_log = logging.getLogger("recording")
# A file without summary is read in write order; records are put back in log-time order
# within this window (the recorder writes them in the order its threads received them).
_REORDER_NS = 2_000_000_000


class RecordingError(ValueError):
    """Not a recording: a missing path, a file that is not MCAP, a damaged file."""


@dataclass(frozen=True, slots=True)
class Record:
    topic: str
    log_time_ns: int
    publish_time_ns: int
    sequence: int
    data: bytes
    schema_name: str
    message_encoding: str


@dataclass
class ChannelSummary:
    topic: str
    schema_name: str
    message_encoding: str
    messages: int = 0


@dataclass
class Recording:
    """The files of one recording (sorted by name: split files are numbered)."""

    files: list[Path]
    truncated: list[Path] = field(default_factory=list)

    @classmethod
    def open(cls, paths: str | Path | Iterable[str | Path]) -> "Recording":
        """A file, a folder (every *.mcap in it), or several files. Raises RecordingError
        when a path is missing or a file is not MCAP."""
        items = [paths] if isinstance(paths, str | Path) else list(paths)
        files: list[Path] = []
        for item in items:
            p = Path(item)
            if p.is_dir():
                found = sorted(p.glob("*.mcap"))
                if not found:
                    raise RecordingError(f"{p}: no .mcap file in this folder")
                files += found
            elif p.is_file():
                files.append(p)
            else:
                raise RecordingError(f"{p}: no such file or folder")
        if not files:
            raise RecordingError("no recording given")
        for f in files:
            _check_magic(f)
        return cls(files)

    def metadata(self) -> dict[str, str]:
        """The recorder's metadata record of the first file ({} when there is none)."""
        path = self.files[0]
        with open(path, "rb") as f:
            if not _complete(path):
                # no summary to seek to: the metadata record follows the header
                try:
                    for m in NonSeekingReader(f, record_size_limit=1 << 30).iter_metadata():
                        if m.name == METADATA_NAME:
                            return dict(m.metadata)
                except (McapError, struct.error):
                    pass                 # cut off before or inside it
                return {}
            try:
                for m in make_reader(f).iter_metadata():
                    if m.name == METADATA_NAME:
                        return dict(m.metadata)
            except McapError as exc:
                raise RecordingError(f"{path}: {exc}") from exc
        return {}

    def channels(self) -> dict[str, ChannelSummary]:
        """Every topic with its schema, encoding and message count (from the summaries;
        a file without one is read through)."""
        out: dict[str, ChannelSummary] = {}
        for path in self.files:
            summary = _summary(path)
            if summary is None or summary.statistics is None:
                for rec in self._iter_file(path, None, None, None):
                    ch = out.setdefault(rec.topic, ChannelSummary(
                        rec.topic, rec.schema_name, rec.message_encoding))
                    ch.messages += 1
                continue
            counts = summary.statistics.channel_message_counts
            for cid, channel in summary.channels.items():
                schema = summary.schemas.get(channel.schema_id)
                ch = out.setdefault(channel.topic, ChannelSummary(
                    channel.topic, schema.name if schema is not None else "",
                    channel.message_encoding))
                ch.messages += counts.get(cid, 0)
        return out

    def time_range(self) -> tuple[int, int]:
        """(first, last) log time in ns. Raises RecordingError for an empty recording."""
        first = last = None
        for path in (self.files[0], self.files[-1]):
            summary = _summary(path)
            if summary is not None and summary.statistics is not None \
                    and summary.statistics.message_count:
                s = summary.statistics
                first = s.message_start_time if first is None else min(first,
                                                                        s.message_start_time)
                last = s.message_end_time if last is None else max(last, s.message_end_time)
        if first is None or last is None:
            times = [r.log_time_ns for r in self.records()]
            if not times:
                raise RecordingError(f"{self.files[0]}: the recording holds no message")
            first, last = min(times), max(times)
        return first, last

    def records(self, topics: Iterable[str] | None = None, start_ns: int | None = None,
                end_ns: int | None = None) -> Iterator[Record]:
        """Every record (of `topics`), log time in [start_ns, end_ns), in log-time order
        across the files."""
        wanted = None if topics is None else set(topics)
        streams = [self._iter_file(p, wanted, start_ns, end_ns) for p in self.files]
        if len(streams) == 1:
            yield from streams[0]
        else:
            yield from heapq.merge(*streams, key=lambda r: r.log_time_ns)

    def _iter_file(self, path: Path, topics: set[str] | None, start_ns: int | None,
                   end_ns: int | None) -> Iterator[Record]:
        if _complete(path):
            with open(path, "rb") as f:
                try:
                    for schema, channel, msg in make_reader(f).iter_messages(
                            topics=topics, starting_at=start_ns, ending_before=end_ns):
                        yield Record(channel.topic, msg.log_time, msg.publish_time,
                                     msg.sequence, msg.data,
                                     schema.name if schema is not None else "",
                                     channel.message_encoding)
                except McapError as exc:
                    raise RecordingError(f"{path}: {exc}") from exc
            return
        if path not in self.truncated:
            self.truncated.append(path)
            _log.warning("recording %s has no summary (its recorder was killed): read up "
                         "to its last complete chunk", path)
        yield from _in_log_order(self._iter_unfinished(path, topics, start_ns, end_ns))

    @staticmethod
    def _iter_unfinished(path: Path, topics: set[str] | None, start_ns: int | None,
                         end_ns: int | None) -> Iterator[Record]:
        with open(path, "rb") as f:
            reader = NonSeekingReader(f, record_size_limit=1 << 30)
            try:
                for schema, channel, msg in reader.iter_messages(
                        topics=topics, starting_at=start_ns, ending_before=end_ns,
                        log_time_order=False):
                    yield Record(channel.topic, msg.log_time, msg.publish_time, msg.sequence,
                                 msg.data, schema.name if schema is not None else "",
                                 channel.message_encoding)
            except (McapError, struct.error):
                # The cut-off record at the end (mcap raises struct.error when the cut falls
                # inside a record's fields): what was written before is all there is.
                return


def _complete(path: Path) -> bool:
    """Whether the file ends with MCAP's closing magic (summary and footer written)."""
    with open(path, "rb") as f:
        f.seek(0, 2)
        if f.tell() < 2 * len(MCAP0_MAGIC):
            return False
        f.seek(-len(MCAP0_MAGIC), 2)
        return f.read() == MCAP0_MAGIC


def _summary(path: Path) -> Any:
    """The file's MCAP summary, None when it has none (unfinished file)."""
    if not _complete(path):
        return None
    with open(path, "rb") as f:
        try:
            return make_reader(f).get_summary()
        except McapError as exc:
            raise RecordingError(f"{path}: {exc}") from exc


def _in_log_order(records: Iterator[Record]) -> Iterator[Record]:
    heap: list[tuple[int, int, Record]] = []
    for n, rec in enumerate(records):
        heapq.heappush(heap, (rec.log_time_ns, n, rec))
        while heap and heap[0][0] < rec.log_time_ns - _REORDER_NS:
            yield heapq.heappop(heap)[2]
    while heap:
        yield heapq.heappop(heap)[2]


def _check_magic(path: Path) -> None:
    with open(path, "rb") as f:
        try:
            make_reader(f).get_header()
        except (InvalidMagic, EndOfFile, struct.error) as exc:   # struct: shorter than a header
            raise RecordingError(f"{path} is not an MCAP recording ({exc})") from exc
        except McapError as exc:
            raise RecordingError(f"{path}: damaged MCAP file ({exc})") from exc


def decode_record(rec: Record) -> tuple[TopicInfo, Any] | None:
    """A stack record's spec and decoded message; None for derived topics and keys no
    spec knows. Raises DecodeError for a payload that is not its key's message."""
    if rec.topic.startswith(DERIVED_PREFIX) or rec.message_encoding != MESSAGE_ENCODING:
        return None
    info = parse_topic(rec.topic)
    if info is None or info.spec.msg_type is None:
        return None
    return info, decode(rec.data, info.spec.msg_type)


__all__ = ["ChannelSummary", "DecodeError", "Record", "Recording", "RecordingError",
           "decode_record"]
