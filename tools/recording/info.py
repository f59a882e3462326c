"""`aeb info REC.mcap`: what a recording holds, as `ros2 bag info` says it: files and size,
duration and time range, and per channel its type, encoding, message count, rate and the
messages its publisher numbered that never reached the recorder.

    aeb info drive.mcap
    aeb info drives/                          # a split recording, as one
    aeb info drive.mcap --json

The counts and the time range come from each file's MCAP summary; the rates and the
dropped messages from reading every record's log time and sequence number (a stack
message's `header.seq`): a large recording takes a while, with progress said every 2 s.
A file whose recorder was killed has no summary and is read to its last complete chunk
(said as `truncated`). Exit codes: 0, 2 when a path is not a readable recording.
"""

import argparse
import json
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from aeb_radar_camera.common.log import add_log_level, setup_logging
from aeb_radar_camera.tools.recording.format import (
    DERIVED_PREFIX,
    METADATA_NAME,
    missed_between,
    parse_topic,
)

if TYPE_CHECKING:      # mcap's reader waits for the arguments (`--help` needs no extra)
    from aeb_radar_camera.tools.recording.reader import Recording

_PROGRESS_S = 2.0


@dataclass
class ChannelInfo:
    topic: str
    type: str
    encoding: str
    messages: int = 0
    first_ns: int = 0
    last_ns: int = 0
    dropped: int | None = None       # None: the channel's messages carry no sequence
    _last_seq: int | None = None

    @property
    def rate_hz(self) -> float | None:
        if self.messages < 2 or self.last_ns <= self.first_ns:
            return None
        return (self.messages - 1) * 1e9 / (self.last_ns - self.first_ns)


@dataclass
class RecordingInfo:
    files: list[str]
    bytes: int
    truncated: list[str]
    metadata: dict[str, str]
    first_ns: int
    last_ns: int
    channels: list[ChannelInfo]

    @property
    def messages(self) -> int:
        return sum(c.messages for c in self.channels)

    @property
    def dropped(self) -> int:
        return sum(c.dropped or 0 for c in self.channels)


def _numbered(topic: str) -> bool:
    """A stack channel whose messages carry a header (and so a sequence number)."""
    info = parse_topic(topic)
    return (info is not None and info.spec.msg_type is not None
            and "header" in info.spec.msg_type.__struct_fields__)


def inspect(rec: "Recording", progress: bool = False) -> RecordingInfo:
    """Everything `aeb info` says of a recording. Raises RecordingError."""
    from aeb_radar_camera.tools.recording.reader import RecordingError

    summaries = rec.channels()
    channels = {t: ChannelInfo(t, s.schema_name or "-", s.message_encoding,
                               dropped=0 if _numbered(t) else None)
                for t, s in sorted(summaries.items())}
    shown = time.monotonic()
    for r in rec.records():
        ch = channels.get(r.topic)
        if ch is None:                   # a file without summary: found while reading
            ch = channels[r.topic] = ChannelInfo(r.topic, r.schema_name or "-",
                                                 r.message_encoding,
                                                 dropped=0 if _numbered(r.topic) else None)
        if ch.messages == 0:
            ch.first_ns = r.log_time_ns
        ch.messages += 1
        ch.last_ns = r.log_time_ns
        if ch.dropped is not None:
            ch.dropped += missed_between(ch._last_seq, r.sequence)
            ch._last_seq = r.sequence
        if progress and time.monotonic() - shown >= _PROGRESS_S:
            shown = time.monotonic()
            print(f"  reading ... {sum(c.messages for c in channels.values())} messages",
                  file=sys.stderr, flush=True)
    heard = [c for c in channels.values() if c.messages]
    if not heard:
        raise RecordingError(f"{rec.files[0]}: the recording holds no message")
    return RecordingInfo(
        files=[str(f) for f in rec.files], bytes=sum(f.stat().st_size for f in rec.files),
        truncated=[str(f) for f in rec.truncated], metadata=rec.metadata(),
        first_ns=min(c.first_ns for c in heard), last_ns=max(c.last_ns for c in heard),
        channels=sorted(channels.values(), key=lambda c: (c.topic.startswith(DERIVED_PREFIX),
                                                          c.topic)))


def _when(ns: int) -> str:
    return (time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(ns / 1e9))
            + f".{ns // 1_000_000 % 1000:03d} UTC ({ns / 1e9:.3f})")


def render(info: RecordingInfo) -> str:
    duration_s = (info.last_ns - info.first_ns) / 1e9
    stack = sum(c.messages for c in info.channels if not c.topic.startswith(DERIVED_PREFIX))
    meta = info.metadata
    dropped_keys = [f"{c.topic} {c.dropped}" for c in info.channels if c.dropped]
    lines = [
        f"Files:      {', '.join(info.files)}",
        f"Size:       {info.bytes / 1e6:.1f} MB ({info.bytes} bytes, {len(info.files)} file"
        f"{'s' if len(info.files) > 1 else ''})",
        f"Recorded:   vehicle {meta.get('vehicle', '?')} by {meta.get('recorder', '?')}"
        + (f", keys {meta['keys']}" if meta.get("keys") else "") if meta else
        f"Recorded:   (no {METADATA_NAME} metadata)",
        f"Duration:   {duration_s:.3f} s",
        f"Start:      {_when(info.first_ns)}",
        f"End:        {_when(info.last_ns)}",
        f"Messages:   {info.messages} ({stack} stack, {info.messages - stack} Foxglove views)",
        f"Dropped:    {info.dropped}" + (f" ({', '.join(dropped_keys)})" if dropped_keys
                                         else "")
        + ": numbered by their publisher, never reached the recorder",
        f"Truncated:  {', '.join(info.truncated) if info.truncated else 'no'}"
        + (" (its recorder was killed: read to the last complete chunk)"
           if info.truncated else ""),
        "",
        f"{'channel':<52} {'type':<28} {'encoding':<9} {'messages':>8} {'rate_hz':>8} "
        f"{'dropped':>7}",
    ]
    for c in info.channels:
        rate = f"{c.rate_hz:8.2f}" if c.rate_hz is not None else f"{'-':>8}"
        dropped = f"{c.dropped:>7}" if c.dropped is not None else f"{'-':>7}"
        lines.append(f"{c.topic:<52} {c.type:<28} {c.encoding:<9} {c.messages:>8} {rate} "
                     f"{dropped}")
    return "\n".join(lines)


def as_json(info: RecordingInfo) -> dict[str, object]:
    return {"files": info.files, "bytes": info.bytes, "truncated": info.truncated,
            "metadata": info.metadata, "first_ns": info.first_ns, "last_ns": info.last_ns,
            "duration_s": (info.last_ns - info.first_ns) / 1e9, "messages": info.messages,
            "dropped": info.dropped,
            "channels": [{k: v for k, v in asdict(c).items() if not k.startswith("_")}
                         | {"rate_hz": c.rate_hz} for c in info.channels]}


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb info", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recording", nargs="+", help="MCAP file(s) or a folder of them")
    parser.add_argument("--json", action="store_true", help="one JSON object")
    add_log_level(parser, "WARNING")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    from aeb_radar_camera.tools.recording.reader import Recording, RecordingError

    setup_logging("info", args.log_level)
    try:
        info = inspect(Recording.open([Path(p) for p in args.recording]),
                       progress=sys.stderr.isatty())
    except RecordingError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(as_json(info), indent=1) if args.json else render(info))
    return 0


if __name__ == "__main__":
    sys.exit(main())
