"""`aeb record`: everything on the vehicle's bus (or a selection of keys) into MCAP, with
the Foxglove views derived beside it (tools/recording/format.py has the layout).

    aeb record -o drive.mcap                              # every key, this host's router
    aeb record -o drive.mcap --connect tcp/192.168.10.1:7447
    aeb record -o drives/run.mcap --split-size 2000 --split-duration 600
    aeb record -o fusion.mcap --keys radar_tracks,camera_jpeg,fusion/primary/*
    aeb record -o drive.mcap --evidence evidence/         # + a folder per WARNING/BRAKE

The raw CAN frames are recorded when the radar publishes them (`[radar.raw_can]`), or
read here from a CAN interface with `--can socketcan:can0`.

Each subscription is a Zenoh FIFO queue read by its own thread, which waits outside
Python's lock: a sample costs Zenoh's receive thread no Python at all, and one writer
thread encodes the views and writes. Ctrl-C or SIGTERM ends it with a complete file
(summary and index); a recorder that is killed leaves the chunks written so far
readable. On exit it says what it wrote: messages and bytes per key, and how many
messages each key's sequence numbers say never arrived.

Exit codes: 0 after a signal or --duration, 2 for bad arguments or no bus.
"""

import argparse
import json
import os
import queue
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import msgspec
import zenoh

from common.bus import Bus
from common.clock import wall_ns
from common.config.fusion import DecisionSettings, FusionConfig
from common.config.loader import ConfigError, load_config
from common.keys import KeySpec, QoS
from common.log import setup_logging
from common.messages import DecodeError, decode
from common.service import stop_event_on_signals
from tools.bus import add_bus_args, open_bus, run_until
from tools.keys import MESSAGE_KEYS
from tools.recording.format import (
    ChannelType,
    channel_of_topic,
    parse_topic,
)
from tools.recording.foxglove_views import Converter, encode_derived
from tools.recording.writer import RecordingWriter, WriterStats

QUEUE_CAPACITY = 8192        # samples per subscription Zenoh may hold for its reader
ALL_KEYS: KeySpec[Any] = KeySpec("all", "**", None, None, None, QoS())


class RecorderStatus(msgspec.Struct, frozen=True):
    """What a running recorder wrote so far (its queryable `record/<pid>/status`)."""

    messages: dict[str, int]     # per key
    derived: int
    queued: int                  # received, not written yet
    dropped: dict[str, int] = msgspec.field(default_factory=dict)  # gaps in the keys' seq


# A tool's key, not the vehicle's: answered on request only.
RECORDER_STATUS: KeySpec[RecorderStatus] = KeySpec(
    "recorder_status", "record/{instance}/status", RecorderStatus, None, None, QoS())


class _Seq(msgspec.Struct):
    header: "_SeqHeader"


class _SeqHeader(msgspec.Struct):
    seq: int
    stamp_ns: int


_seq_decoder = msgspec.msgpack.Decoder(_Seq)


@dataclass
class KeyStats:
    messages: int = 0
    bytes: int = 0
    dropped: int = 0           # sequence numbers that never arrived
    undecodable: int = 0       # recorded all the same
    last_seq: int | None = None


@dataclass
class RecordStats:
    keys: dict[str, KeyStats] = field(default_factory=dict)
    derived: int = 0
    derived_errors: int = 0
    started_ns: int = 0
    ended_ns: int = 0
    files: list[str] = field(default_factory=list)
    bytes_on_disk: int = 0

    def as_json(self) -> dict[str, Any]:
        return {"files": self.files, "bytes_on_disk": self.bytes_on_disk,
                "duration_s": (self.ended_ns - self.started_ns) / 1e9,
                "derived_messages": self.derived, "derived_errors": self.derived_errors,
                "keys": {k: {"messages": s.messages, "bytes": s.bytes, "dropped": s.dropped,
                             "undecodable": s.undecodable} for k, s in self.keys.items()}}


def selection(keys: str, vehicle: str) -> list[str]:
    """Key expressions for `--keys`: spec names (``camera_jpeg``), keys relative to the
    vehicle (``fusion/*/targets``) or whole (``aeb/ego/...``). Empty: everything.
    Raises ValueError for an empty item."""
    if not keys:
        return [ALL_KEYS.wildcard(vehicle)]
    by_name = {s.name: s for s in MESSAGE_KEYS}
    out = []
    for item in (k.strip() for k in keys.split(",")):
        if not item:
            raise ValueError("--keys has an empty item")
        if item in by_name:
            out.append(by_name[item].wildcard(vehicle))
        elif item.startswith("aeb/"):
            out.append(item)
        else:
            out.append(f"aeb/{vehicle}/{item}")
    return out


class Writer(Protocol):
    """Where the recorder writes: an MCAP file (RecordingWriter), or the live Foxglove
    server (tools/foxglove/bridge.py)."""

    def write(self, topic: str, kind: ChannelType, payload: bytes, log_time_ns: int,
              publish_time_ns: int, sequence: int = 0) -> None: ...

    def close(self) -> WriterStats: ...


class Recorder:
    """Subscribes to `exprs`, writes into `writer` (None: writes nothing, for the sinks
    alone); `converter` derives the Foxglove views (None: only the stack's channels);
    `sinks` get every decoded stack message too (the evidence collector); `keep(key,
    log_ns)` may leave samples out (the bridge's frame rate limit)."""

    def __init__(self, bus: Bus, writer: Writer | None, exprs: list[str],
                 converter: Converter | None, sinks: tuple[Any, ...] = (),
                 capacity: int = QUEUE_CAPACITY,
                 keep: Callable[[str, int], bool] | None = None) -> None:
        self.bus = bus
        self.writer = writer
        self.keep = keep
        self.exprs = exprs
        self.converter = converter
        self.sinks = sinks
        self.capacity = capacity
        self.stats = RecordStats()
        self._queue: queue.SimpleQueue[tuple[str, bytes, int] | None] = queue.SimpleQueue()
        self._subs: list[zenoh.Subscriber[zenoh.Handler[zenoh.Sample]]] = []
        self._readers: list[threading.Thread] = []
        self._health: Any = None
        self._writer_thread = threading.Thread(target=self._write_loop, name="record-writer",
                                               daemon=True)
        self.write_error: BaseException | None = None

    def start(self) -> None:
        self.stats.started_ns = wall_ns()
        self._writer_thread.start()
        prefix = f"aeb/{self.bus.vehicle}/"
        for expr in self.exprs:
            if not expr.startswith(prefix):
                raise ValueError(f"key {expr!r} is not under {prefix}")
            spec: KeySpec[Any] = KeySpec("record", expr.removeprefix(prefix), None, None,
                                         None, QoS())
            sub = self.bus.subscribe_queued(spec, self.capacity)
            self._subs.append(sub)
            reader = threading.Thread(target=self._read_loop, args=(sub.handler,),
                                      name=f"record-{expr}", daemon=True)
            reader.start()
            self._readers.append(reader)
        if self.converter is not None:
            self._health = self.bus.subscribe_health(self._on_health)

    def _read_loop(self, handler: zenoh.Handler[zenoh.Sample]) -> None:
        # recv() waits without the GIL; it raises once the subscriber is undeclared.
        while True:
            try:
                sample = handler.recv()
            except zenoh.ZError:
                return
            if sample.kind == zenoh.SampleKind.PUT:
                self._queue.put((str(sample.key_expr), sample.payload.to_bytes(), wall_ns()))

    def status(self) -> RecorderStatus:
        keys = list(self.stats.keys.items())
        return RecorderStatus({k: s.messages for k, s in keys}, self.stats.derived,
                              self._queue.qsize(), {k: s.dropped for k, s in keys if s.dropped})

    def submit(self, key: str, payload: bytes, log_ns: int) -> None:
        """A payload from another source (the CAN reader), recorded as if received on
        `key`."""
        self._queue.put((key, payload, log_ns))

    def _on_health(self, service: str, instance: str, alive: bool) -> None:
        self._queue.put((f"\0health\0{service}\0{instance}\0{int(alive)}", b"", wall_ns()))

    def _write_loop(self) -> None:
        try:
            while (item := self._queue.get()) is not None:
                self._write(*item)
        except BaseException as exc:  # reported by stop(); the file is closed there
            self.write_error = exc
            while self._queue.get() is not None:
                pass

    def _write(self, key: str, payload: bytes, log_ns: int) -> None:
        if key.startswith("\0health\0"):
            _, _, service, instance, alive = key.split("\0")
            assert self.converter is not None
            self._derived([self.converter.health(service, instance, alive == "1")], log_ns)
            return
        if self.keep is not None and not self.keep(key, log_ns):
            return
        stats = self.stats.keys.get(key)
        if stats is None:
            stats = self.stats.keys[key] = KeyStats()
        stats.messages += 1
        stats.bytes += len(payload)
        pub_ns, seq = log_ns, 0
        try:
            head = _seq_decoder.decode(payload).header
            pub_ns, seq = head.stamp_ns, head.seq
            if stats.last_seq is not None and seq > stats.last_seq + 1:
                stats.dropped += seq - stats.last_seq - 1
            stats.last_seq = seq
        except (msgspec.DecodeError, msgspec.ValidationError):
            pass
        if self.writer is not None:
            self.writer.write(key, channel_of_topic(key), payload, log_ns, pub_ns, seq)
        if self.converter is None and not self.sinks:
            return
        info = parse_topic(key)
        if info is None or info.spec.msg_type is None:
            return
        try:
            msg = decode(payload, info.spec.msg_type)
        except DecodeError:
            stats.undecodable += 1
            return
        for sink in self.sinks:
            sink.on_message(info.spec.name, key, msg, payload, log_ns)
        if self.converter is not None:
            try:
                derived = self.converter.convert(info.spec.name, msg)
            except ValueError:           # e.g. a JPEG that does not decode when scaled
                self.stats.derived_errors += 1
                return
            self._derived(derived, log_ns)

    def _derived(self, derived: list[tuple[str, Any]], log_ns: int) -> None:
        if self.writer is None:
            return
        for topic, view in derived:
            kind, data = encode_derived(view)
            self.writer.write(topic, kind, data, log_ns, log_ns)
            self.stats.derived += 1

    def stop(self) -> RecordStats:
        """Stop receiving, write everything received, close the files."""
        if self._health is not None:
            self._health.undeclare()
        for sub in self._subs:
            sub.undeclare()
        for reader in self._readers:
            reader.join(5)
        self._queue.put(None)
        self._writer_thread.join()
        for sink in self.sinks:
            sink.close()
        self.stats.ended_ns = wall_ns()
        if self.writer is not None:
            written: WriterStats = self.writer.close()
            self.stats.files = [str(p) for p in written.files]
            self.stats.bytes_on_disk = written.bytes_on_disk
        return self.stats


def summary_text(stats: RecordStats) -> str:
    minutes = max(1e-9, (stats.ended_ns - stats.started_ns) / 60e9)
    lines = [f"wrote {len(stats.files)} file(s), {stats.bytes_on_disk / 1e6:.1f} MB in "
             f"{minutes * 60:.1f} s ({stats.bytes_on_disk / 1e6 / minutes:.1f} MB/min): "
             + ", ".join(stats.files),
             f"{'key':<44} {'messages':>9} {'MB':>9} {'dropped':>7} {'undecodable':>12}"]
    for key, s in sorted(stats.keys.items()):
        lines.append(f"{key:<44} {s.messages:>9} {s.bytes / 1e6:>9.2f} {s.dropped:>7} "
                     f"{s.undecodable:>12}")
    total = sum(s.messages for s in stats.keys.values())
    dropped = sum(s.dropped for s in stats.keys.values())
    lines.append(f"{'total':<44} {total:>9} {sum(s.bytes for s in stats.keys.values()) / 1e6:>9.2f}"
                 f" {dropped:>7} {sum(s.undecodable for s in stats.keys.values()):>12}")
    lines.append(f"derived Foxglove messages: {stats.derived}"
                 + (f" ({stats.derived_errors} could not be derived)"
                    if stats.derived_errors else ""))
    lines.append("dropped: messages the publisher numbered, between the first and the last "
                 "recorded, that never reached the recorder")
    return "\n".join(lines)


def decision_settings(path: str) -> DecisionSettings:
    """The corridor and ranges the scene views draw: from a fusion config, or the
    defaults. Raises ConfigError."""
    if not path:
        return DecisionSettings()
    return load_config(path, FusionConfig).fusion.decision


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb record", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-o", "--out", default="recording.mcap", help="the MCAP file")
    add_bus_args(parser, connect_timeout_s=0.0)
    parser.add_argument("--keys", default="",
                        help="comma-separated key names or expressions (default: every key)")
    parser.add_argument("--split-size", type=float, default=None, metavar="MB",
                        help="start a new file after this many MB")
    parser.add_argument("--split-duration", type=float, default=None, metavar="S",
                        help="start a new file after this many seconds")
    parser.add_argument("--duration", type=float, default=None,
                        help="stop after this many seconds (default: at Ctrl-C)")
    parser.add_argument("--compression", choices=["zstd", "lz4", "none"], default="zstd")
    parser.add_argument("--no-views", action="store_true",
                        help="only the stack's channels, no derived Foxglove channels")
    parser.add_argument("--fusion-config", default="",
                        help="fusion config whose corridor the scene draws (default: the "
                             "shipped defaults)")
    parser.add_argument("--evidence", default="", metavar="DIR",
                        help="also write an evidence folder per WARNING and BRAKE here")
    parser.add_argument("--can", default="", metavar="INTERFACE:CHANNEL[:BUS]",
                        help="also read raw CAN frames from this python-can interface")
    parser.add_argument("--summary-json", default="", help="write the exit summary here too")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging("record", args.log_level)
    stop = stop_event_on_signals()
    try:
        exprs = selection(args.keys, args.vehicle)
        converter = None if args.no_views else Converter(
            args.vehicle, decision_settings(args.fusion_config))
        writer = RecordingWriter(
            args.out, split_bytes=None if args.split_size is None else int(args.split_size * 1e6),
            split_s=args.split_duration, compression=args.compression,
            metadata={"vehicle": args.vehicle, "keys": ",".join(exprs),
                      "recorder": "aeb record"})
    except (ValueError, ConfigError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    sinks: list[Any] = []
    if args.evidence:
        from tools.recording.evidence import EvidenceCollector

        sinks.append(EvidenceCollector(Path(args.evidence), args.vehicle,
                                       decision_settings(args.fusion_config)))
    bus = open_bus(args, "record", stop)
    with bus:
        recorder = Recorder(bus, writer, exprs, converter, tuple(sinks))
        can_reader = None
        try:
            recorder.start()
            if args.can:
                from tools.recording.can_reader import CanReader

                can_reader = CanReader.from_spec(args.can, args.vehicle, recorder.submit)
                can_reader.start()
        except (ValueError, OSError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            recorder.stop()
            return 2
        # Declared once subscribed: seeing it means the recorder is recording.
        status = bus.declare_queryable(RECORDER_STATUS, recorder.status,
                                       instance=str(os.getpid()))
        token = bus.declare_health("record", str(os.getpid()))
        print(f"recording {', '.join(exprs)} into {args.out} (Ctrl-C to stop)",
              file=sys.stderr, flush=True)
        run_until(stop, args.duration, lambda: recorder.write_error is not None)
        token.undeclare()
        status.undeclare()
        if can_reader is not None:
            can_reader.stop()
        stats = recorder.stop()
    print(summary_text(stats), file=sys.stderr, flush=True)
    if args.summary_json:
        Path(args.summary_json).write_text(json.dumps(stats.as_json(), indent=1))
    if recorder.write_error is not None:
        print(f"error: writing stopped: {recorder.write_error!r}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
