"""The recorder behind `aeb record`, `aeb evidence` and `aeb foxglove`: subscribes to key
expressions of one vehicle and hands every sample to a writer (an MCAP file, the live
Foxglove server) with the Foxglove views derived beside it, and to sinks (the evidence
collector).

Each subscription is a Zenoh FIFO queue read by its own thread, which waits outside
Python's lock: a sample costs Zenoh's receive thread no Python at all, and one writer
thread encodes the views and writes. It counts, per key, messages, bytes, messages whose
sequence numbers say they never arrived and payloads that do not decode.
"""


import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import msgspec
import zenoh

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.clock import wall_ns
from aeb_radar_camera.common.config.fusion import DecisionSettings, FusionConfig
from aeb_radar_camera.common.config.loader import load_config
from aeb_radar_camera.common.keys import KeySpec, QoS
from aeb_radar_camera.common.messages import DecodeError, decode
from aeb_radar_camera.tools.keys import MESSAGE_KEYS
from aeb_radar_camera.tools.recording.format import (
    ChannelType,
    channel_of_topic,
    missed_between,
    parse_topic,
)
from aeb_radar_camera.tools.recording.foxglove_views import Converter, encode_derived
from aeb_radar_camera.tools.recording.writer import WriterStats

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
            stats.dropped += missed_between(stats.last_seq, seq)
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


def decision_settings(path: str) -> DecisionSettings:
    """The corridor and ranges the scene views draw: from a fusion config, or the
    defaults. Raises ConfigError."""
    if not path:
        return DecisionSettings()
    return load_config(path, FusionConfig).fusion.decision
