"""`aeb replay`: a recording published back on the bus, for the stack to run on.

    aeb replay drive.mcap                                  # every stack key, original timing
    aeb replay drive.mcap --keys radar_tracks,camera_jpeg,camera_info   # fusion's inputs
    aeb replay drive.mcap --rate 0.5 --start 30 --end 90 --loop
    aeb replay drive.mcap --fast                           # as fast as the subscribers take it
    aeb replay drive.mcap --vehicle replay1                # into another vehicle id
    aeb replay drive.mcap --remap fusion/primary=fusion/recorded
    aeb replay drive.mcap --can-pty                        # raw CAN to a radar service
    aeb replay drive.mcap --can-bus socketcan:can0         # raw CAN onto a real bus

Messages are re-stamped so that the stack takes them as live: every wall-clock stamp is
mapped onto now (recorded time t -> start + (t - first) / rate), and monotonic fields
are shifted onto this host's clock keeping their differences; `--keep-stamps` publishes
the recorded bytes unchanged. With `--loop`, sequence numbers go on increasing from one
pass to the next. Only the stack's own channels are published (not the Foxglove views).

Raw CAN (`can/<bus>/frames`) also goes to a CAN interface at the recorded frame times,
for a radar service reading it unchanged: `--can-bus INTERFACE:CHANNEL` (python-can; a
real or virtual bus), or `--can-pty`, a pseudo-terminal that behaves as an slcan USB-CAN
adapter (a SIMULATION of the adapter's wire: point `[radar.can]` at the printed path with
interface "slcan").

On a terminal, keys control it as `ros2 bag play`'s do (tools/recording/keyboard.py):
space pauses and resumes, s or the right arrow sends the next message alone, the up and
down arrows (or + and -) make it 10% faster or slower; `--no-keys` leaves the terminal
alone.

Exit codes: 0 at the end (or on a signal), 2 for bad arguments, recording or bus.
"""

import argparse
import sys
import threading
import time
from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import msgspec

from aeb_radar_camera.common.bus import Bus, TypedPublisher
from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.keys import Congestion, KeySpec, QoS
from aeb_radar_camera.common.log import setup_logging
from aeb_radar_camera.common.messages import (
    BrakeCommand,
    BrakeStatus,
    DecodeError,
    RadarTracks,
    RawCanFrames,
    decode,
    encode,
)
from aeb_radar_camera.common.messages.radar import CAN_ERROR, CanFrame, can_message
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.tools.bus import add_bus_args, open_bus
from aeb_radar_camera.tools.keys import MESSAGE_KEYS
from aeb_radar_camera.tools.recording.format import DERIVED_PREFIX, parse_topic
from aeb_radar_camera.tools.recording.keyboard import keyboard
from aeb_radar_camera.tools.recording.playback import Playback, TimeMap

if TYPE_CHECKING:      # mcap's reader waits for the arguments (`--help` needs no extra)
    from aeb_radar_camera.tools.recording.reader import Record, Recording

GENERIC: KeySpec[Any] = KeySpec("replayed", "**", None, None, None, QoS())


def select_topics(topics: list[str], keys: str, skip: str) -> list[str]:
    """The stack topics to publish: all, or those matching `keys` (spec names or key
    expressions relative to the vehicle, `*` for one chunk), minus `skip`."""
    stack = [t for t in topics if not t.startswith(DERIVED_PREFIX)]

    def matcher(spec: str) -> Callable[[str], bool]:
        names = {s.name for s in MESSAGE_KEYS}
        items = [k.strip() for k in spec.split(",") if k.strip()]
        for item in items:
            if item not in names and "/" not in item:
                raise ValueError(f"{item!r} is neither a key name nor a key expression")

        def match(topic: str) -> bool:
            info = parse_topic(topic)
            rel = topic.split("/", 2)[2] if topic.count("/") >= 2 else topic
            for item in items:
                if info is not None and item == info.spec.name:
                    return True
                if "/" in item and _expr_match(item, rel):
                    return True
            return False
        return match

    if keys:
        wanted = matcher(keys)
        stack = [t for t in stack if wanted(t)]
    if skip:
        unwanted = matcher(skip)
        stack = [t for t in stack if not unwanted(t)]
    return stack


def _expr_match(expr: str, key: str) -> bool:
    a, b = expr.split("/"), key.split("/")
    if a and a[-1] == "**":
        return len(b) >= len(a) - 1 and all(x in ("*", y) for x, y in zip(a[:-1], b,
                                                                          strict=False))
    return len(a) == len(b) and all(x in ("*", y) for x, y in zip(a, b, strict=True))


def restamp(msg: Any, tm: TimeMap, log_ns: int, now_wall: int, now_mono: int,
            seq_offset: int) -> Any:
    """The message with its stamps on the replay's clocks and its sequence number
    offset (loops)."""
    h = msg.header
    d_mono = now_mono - h.pub_mono_ns
    header = msgspec.structs.replace(h, seq=h.seq + seq_offset,
                                     stamp_ns=tm.wall(h.stamp_ns, log_ns, now_wall),
                                     pub_mono_ns=now_mono)
    changes: dict[str, Any] = {"header": header}
    if isinstance(msg, RadarTracks):
        changes["last_frame_mono_ns"] = msg.last_frame_mono_ns + d_mono
    elif isinstance(msg, BrakeCommand):
        changes["radar_last_frame_mono_ns"] = msg.radar_last_frame_mono_ns + d_mono
    elif isinstance(msg, BrakeStatus):
        changes["state_since_mono_ns"] = msg.state_since_mono_ns and \
            msg.state_since_mono_ns + d_mono
        changes["last_cmd_rx_mono_ns"] = msg.last_cmd_rx_mono_ns and \
            msg.last_cmd_rx_mono_ns + d_mono
    elif isinstance(msg, RawCanFrames):
        changes["frames"] = tuple(msgspec.structs.replace(
            f, rx_wall_ns=tm.wall(f.rx_wall_ns, log_ns, now_wall),
            rx_mono_ns=f.rx_mono_ns + d_mono) for f in msg.frames)
    return msgspec.structs.replace(msg, **changes)


@dataclass
class ReplayStats:
    published: dict[str, int] = field(default_factory=dict)
    undecodable: int = 0
    can_frames: int = 0
    loops: int = 0


class CanOut:
    """Raw CAN frames to a CAN interface at their recorded times."""

    def __init__(self, send: Callable[[list[CanFrame]], None]) -> None:
        self.send = send

    @classmethod
    def bus(cls, spec: str) -> tuple["CanOut", Callable[[], None]]:
        """`INTERFACE:CHANNEL` through python-can. Raises ValueError, OSError."""
        import can

        interface, sep, channel = spec.partition(":")
        if not sep or not interface or not channel:
            raise ValueError(f"--can-bus {spec!r}: expected INTERFACE:CHANNEL")
        try:
            bus = can.Bus(interface=interface, channel=channel)
        except can.CanError as exc:
            raise OSError(f"--can-bus {spec}: {exc}") from exc

        def send(frames: list[CanFrame]) -> None:
            for f in frames:
                bus.send(can_message(f))

        return cls(send), bus.shutdown

    @classmethod
    def pty(cls, stop: threading.Event, path_file: str = "") -> tuple["CanOut", Callable[[], None]]:
        """A pty acting as an slcan adapter (SIMULATION of the wire); waits until a
        service opened it."""
        from aeb_radar_camera.services.radar.ars408.codec import RadarFrame
        from aeb_radar_camera.tools.sim.can_links import SlcanPtyLink

        link = SlcanPtyLink()
        print(f"slcan adapter (simulated wire) on {link.path}: [radar.can] interface = "
              f'"slcan", channel = "{link.path}", options = {{ sleep_after_open = 0 }}',
              file=sys.stderr, flush=True)
        if path_file:
            Path(path_file).write_text(link.path)
        while not stop.is_set() and not link.opened:
            stop.wait(0.05)

        def send(frames: list[CanFrame]) -> None:
            link.send(RadarFrame(f.arb_id, f.data) for f in frames if not f.flags)

        return cls(send), link.close


class Replayer:
    """Publishes a recording's messages when `playback` lets each out (its rate, pauses
    and steps)."""

    def __init__(self, bus: Bus, recording: "Recording", topics: list[str], playback: Playback,
                 keep_stamps: bool, vehicle_map: Callable[[str], str],
                 can_out: CanOut | None = None) -> None:
        self.bus = bus
        self.recording = recording
        self.topics = topics
        self.playback = playback
        self.fast = playback.fast
        self.keep_stamps = keep_stamps
        self.vehicle_map = vehicle_map
        self.can_out = can_out
        self.stats = ReplayStats()
        self._pubs: dict[str, TypedPublisher[Any]] = {}
        self._seq_span: dict[str, tuple[int, int]] = {}

    def _publisher(self, topic: str) -> TypedPublisher[Any]:
        pub = self._pubs.get(topic)
        if pub is None:
            info = parse_topic(topic)
            spec = info.spec if info is not None else GENERIC
            if self.fast:
                # As fast as subscribers take it: wait on congestion rather than drop.
                spec = replace(spec, qos=replace(spec.qos, congestion=Congestion.BLOCK))
            pub = self._pubs[topic] = TypedPublisher(self.bus.session, spec,
                                                     self.vehicle_map(topic))
        return pub

    def run(self, stop: threading.Event, start_ns: int | None, end_ns: int | None,
            loop: bool, progress: Callable[[int, int], None]) -> None:
        first, last = self.recording.time_range()
        t0 = start_ns if start_ns is not None else first
        t1 = end_ns if end_ns is not None else last + 1
        seq_offset = 0
        while not stop.is_set():
            self.playback.start(t0)
            spans: dict[str, tuple[int, int]] = {}
            for rec in self.recording.records(self.topics, t0, t1):
                if not self.playback.wait_due(rec.log_time_ns, stop):
                    return
                self._publish(rec, self.playback.time_map(), seq_offset, spans)
                progress(rec.log_time_ns - t0, t1 - t0)
            if not loop:
                return
            self.stats.loops += 1
            # The next pass numbers on from this one's highest sequence number.
            seq_offset += max((hi - lo + 1 for lo, hi in spans.values()), default=0)

    def _publish(self, rec: "Record", tm: TimeMap, seq_offset: int,
                 spans: dict[str, tuple[int, int]]) -> None:
        info = parse_topic(rec.topic)
        payload = rec.data
        msg: Any = None
        if info is not None and info.spec.msg_type is not None:
            try:
                msg = decode(rec.data, info.spec.msg_type)
            except DecodeError:
                self.stats.undecodable += 1
        if msg is not None and hasattr(msg, "header"):
            lo, hi = spans.get(rec.topic, (msg.header.seq, msg.header.seq))
            spans[rec.topic] = (min(lo, msg.header.seq), max(hi, msg.header.seq))
            if not self.keep_stamps:
                msg = restamp(msg, tm, rec.log_time_ns, wall_ns(), mono_ns(), seq_offset)
                payload = encode(msg)
        if isinstance(msg, RawCanFrames) and self.can_out is not None:
            self._send_can(msg)
        self._publisher(rec.topic).put_bytes(payload)
        self.stats.published[rec.topic] = self.stats.published.get(rec.topic, 0) + 1

    def _send_can(self, batch: RawCanFrames) -> None:
        assert self.can_out is not None
        frames = [f for f in batch.frames if not f.flags & CAN_ERROR]
        if not frames:
            return
        # The batch follows its frames: send them at their recorded spacing from now.
        base = frames[0].rx_mono_ns
        start = mono_ns()
        group: list[CanFrame] = []
        rate = self.playback.rate
        for f in frames:
            due = start + (f.rx_mono_ns - base) / rate
            if due - mono_ns() > 1_000_000 and group:
                self.can_out.send(group)
                group = []
                time.sleep(max(0.0, (due - mono_ns()) / 1e9))
            group.append(f)
        if group:
            self.can_out.send(group)
        self.stats.can_frames += len(frames)


def vehicle_mapper(vehicle: str, remaps: list[str]) -> Callable[[str], str]:
    """Recorded key -> key to publish on: another vehicle id, then `OLD=NEW` prefix
    replacements relative to the vehicle. Raises ValueError for a malformed remap."""
    pairs = []
    for item in remaps:
        old, sep, new = item.partition("=")
        if not sep or not old or not new:
            raise ValueError(f"--remap {item!r}: expected OLD=NEW")
        pairs.append((old.strip("/"), new.strip("/")))

    def mapped(topic: str) -> str:
        _, _, rest = topic.split("/", 2)
        for old, new in pairs:
            if rest == old or rest.startswith(old + "/"):
                rest = new + rest[len(old):]
                break
        return f"aeb/{vehicle}/{rest}"
    return mapped


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb replay", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recording", nargs="+", help="MCAP file(s) or a folder of them")
    add_bus_args(parser, connect_timeout_s=0.0, listen=True)
    speed = parser.add_mutually_exclusive_group()
    speed.add_argument("--rate", type=float, default=1.0, help="time factor (2: twice as fast)")
    speed.add_argument("--fast", action="store_true",
                       help="as fast as the subscribers take it (no pauses)")
    parser.add_argument("--start", type=float, default=None,
                        help="start this many seconds into the recording")
    parser.add_argument("--end", type=float, default=None,
                        help="end this many seconds into the recording")
    parser.add_argument("--loop", action="store_true")
    parser.add_argument("--keys", default="", help="only these keys (names or expressions)")
    parser.add_argument("--skip", default="", help="not these keys")
    parser.add_argument("--remap", action="append", default=[], metavar="OLD=NEW",
                        help="key prefix remap under the vehicle, e.g. fusion/primary=fusion/old")
    parser.add_argument("--keep-stamps", action="store_true",
                        help="publish the recorded bytes, stamps unchanged")
    parser.add_argument("--can-bus", default="", metavar="INTERFACE:CHANNEL",
                        help="also send the raw CAN frames onto this python-can bus")
    parser.add_argument("--can-pty", action="store_true",
                        help="also send the raw CAN frames to an slcan pty (SIMULATION)")
    parser.add_argument("--can-pty-path-file", default="", help=argparse.SUPPRESS)
    parser.add_argument("--wait-for", default="", metavar="SERVICE/INSTANCE",
                        help="start once this liveliness token is up (e.g. fusion/primary)")
    parser.add_argument("--quiet", action="store_true", help="no progress lines")
    parser.add_argument("--no-keys", action="store_true",
                        help="do not read keys from the terminal (pause, step, rate)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    from aeb_radar_camera.tools.recording.reader import Recording, RecordingError

    setup_logging("replay", args.log_level)
    stop = stop_event_on_signals()
    if args.rate <= 0:
        print("error: --rate must be positive", file=sys.stderr)
        return 2
    try:
        rec = Recording.open(args.recording)
        recorded_vehicle = rec.metadata().get("vehicle", "ego")
        topics = select_topics(sorted(rec.channels()), args.keys, args.skip)
        if args.vehicle == "ego":           # the default: the recording's own vehicle
            args.vehicle = recorded_vehicle
        mapper = vehicle_mapper(args.vehicle, args.remap)
        first, last = rec.time_range()
    except (RecordingError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if not topics:
        print("error: no stack key of the recording is selected", file=sys.stderr)
        return 2
    start = None if args.start is None else first + round(args.start * 1e9)
    end = None if args.end is None else first + round(args.end * 1e9)
    bus = open_bus(args, "replay", stop)
    closers: list[Callable[[], None]] = []
    with bus:
        can_out = None
        try:
            if args.can_bus:
                can_out, close = CanOut.bus(args.can_bus)
                closers.append(close)
            elif args.can_pty:
                can_out, close = CanOut.pty(stop, args.can_pty_path_file)
                closers.append(close)
        except (ValueError, OSError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        if args.wait_for:
            _wait_for_token(bus, args.wait_for, stop)
        playback = Playback(args.rate, args.fast, mono_ns, wall_ns)
        replayer = Replayer(bus, rec, topics, playback, args.keep_stamps, mapper, can_out)
        span_s = ((end or last) - (start or first)) / 1e9
        print(f"replaying {len(topics)} keys, {span_s:.1f} s"
              + (" as fast as possible" if args.fast else f" at {args.rate:g}x"),
              file=sys.stderr, flush=True)
        shown = [time.monotonic()]

        def progress(done_ns: int, total_ns: int) -> None:
            now = time.monotonic()
            if not args.quiet and now - shown[0] >= 2.0:
                shown[0] = now
                n = sum(replayer.stats.published.values())
                print(f"  {done_ns / 1e9:7.1f} / {total_ns / 1e9:.1f} s "
                      f"({100 * done_ns / max(1, total_ns):5.1f}%)  {n} messages",
                      file=sys.stderr, flush=True)

        def say(text: str) -> None:
            print(text, file=sys.stderr, flush=True)

        try:
            with keyboard(playback, stop, say) if not args.no_keys else nullcontext():
                replayer.run(stop, start, end, args.loop, progress)
        finally:
            for close in closers:
                close()
    st = replayer.stats
    print(f"published {sum(st.published.values())} messages"
          + (f", {st.can_frames} CAN frames" if st.can_frames else "")
          + (f", {st.loops} loops" if st.loops else "")
          + (f"; {st.undecodable} undecodable (published as recorded)" if st.undecodable else ""),
          file=sys.stderr)
    for topic, n in sorted(st.published.items()):
        print(f"  {mapper(topic):<44} {n:>8}", file=sys.stderr)
    return 0


def _wait_for_token(bus: Bus, token: str, stop: threading.Event) -> None:
    service, _, instance = token.partition("/")
    seen = threading.Event()

    def on_health(s: str, i: str, alive: bool) -> None:
        if s == service and (not instance or i == instance) and alive:
            seen.set()

    sub = bus.subscribe_health(on_health)
    print(f"waiting for health/{token} ...", file=sys.stderr, flush=True)
    while not stop.is_set() and not seen.wait(0.1):
        pass
    sub.undeclare()


if __name__ == "__main__":
    sys.exit(main())
