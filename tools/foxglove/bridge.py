"""`aeb foxglove`: the live bus in Foxglove, over its WebSocket protocol (foxglove-sdk).

    aeb foxglove                                       # ws://127.0.0.1:8765, this host's router
    aeb foxglove --connect tcp/192.168.10.1:7447 --host 0.0.0.0
    aeb foxglove --max-fps 5 --scale 0.5               # a remote viewer on a slow link

Open Foxglove, "Open connection", Foxglove WebSocket, `ws://HOST:8765`. The channels are
those of a recording (tools/recording/foxglove_views.py, docs/monitoring.md lists them): the
camera (`/foxglove/<vehicle>/camera/<camera>/image`) with each fusion instance's ROIs
(`.../fusion/<instance>/annotations/<camera>`), the tracks from above with the corridor
(`.../fusion/<instance>/scene`, `.../radar/<sensor>/scene`), JSON views for plots (TTC,
density, decision, brake level) and every service's health; and every stack key itself
as JSON (topic = the key; Foxglove's WebSocket client does not read msgpack), the camera
frames excepted (the image channel carries them).

`--max-fps` keeps at most that many frames per second per camera (the others are not
sent at all); `--scale` resizes them (and their annotations) before sending.

Exit codes: 0 after a signal or --duration, 2 for bad arguments, no bus or no port.
"""

import argparse
import errno
import os
import sys
import threading
from typing import TYPE_CHECKING, Any

import msgspec

from aeb_radar_camera.common.keys import CAMERA_JPEG
from aeb_radar_camera.common.log import setup_logging
from aeb_radar_camera.common.messages import DecodeError, decode
from aeb_radar_camera.common.messages.schema import schema_name
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.tools.bus import add_bus_args, open_bus, run_until
from aeb_radar_camera.tools.commands import DEFAULT_PORTS, port_in_use
from aeb_radar_camera.tools.recording.format import ChannelType, parse_topic

# foxglove-sdk and the views are imported once the arguments are read: `--help` needs no
# extra installed
if TYPE_CHECKING:
    import foxglove

    from aeb_radar_camera.tools.recording.writer import WriterStats


class FoxgloveSink:
    """The recorder's writer interface onto a foxglove-sdk context: a channel per topic,
    created on its first message (the server advertises it then). Stack channels
    (msgpack) are sent as JSON with their schema; the camera's raw frames are left out
    (the image channel has them)."""

    def __init__(self, context: "foxglove.Context") -> None:
        from aeb_radar_camera.tools.recording.writer import TopicCount, WriterStats

        self.context = context
        self.stats = WriterStats()
        self._new_count = TopicCount
        self._channels: dict[str, foxglove.Channel] = {}
        self._json: dict[type[Any], foxglove.Schema] = {}
        self._lock = threading.Lock()

    def _channel(self, topic: str, kind: ChannelType) -> "foxglove.Channel":
        import foxglove

        channel = self._channels.get(topic)
        if channel is None:
            schema = foxglove.Schema(name=kind.schema_name, encoding=kind.schema_encoding,
                                     data=kind.schema_data)
            channel = self._channels[topic] = foxglove.Channel(
                topic, schema=schema, message_encoding=kind.message_encoding,
                context=self.context)
        return channel

    def write(self, topic: str, kind: ChannelType, payload: bytes, log_time_ns: int,
              publish_time_ns: int, sequence: int = 0) -> None:
        if kind.message_encoding == "msgpack":
            converted = self._as_json(topic, payload)
            if converted is None:
                return
            kind, payload = converted
        with self._lock:
            self._channel(topic, kind).log(payload, log_time=log_time_ns)
            count = self.stats.topics.setdefault(topic, self._new_count())
            count.messages += 1
            count.bytes += len(payload)

    def _as_json(self, topic: str, payload: bytes) -> tuple[ChannelType, bytes] | None:
        info = parse_topic(topic)
        if info is None or info.spec.msg_type is None or info.spec is CAMERA_JPEG:
            return None
        from aeb_radar_camera.tools.recording.foxglove_views import object_schema

        msg_type = info.spec.msg_type
        try:
            msg = decode(payload, msg_type)
        except DecodeError:
            return None
        schema = msgspec.json.encode(object_schema(msg_type))
        return ChannelType(schema_name(msg_type), "jsonschema", schema, "json"), \
            msgspec.json.encode(msg)

    def close(self) -> "WriterStats":
        with self._lock:
            for channel in self._channels.values():
                channel.close()
            self._channels.clear()
        return self.stats


class FrameLimit:
    """At most `max_fps` camera frames per second per camera (0: all)."""

    def __init__(self, max_fps: float) -> None:
        self.period_ns = round(1e9 / max_fps) if max_fps > 0 else 0
        self._last: dict[str, int] = {}

    def __call__(self, key: str, log_ns: int) -> bool:
        if not self.period_ns or not key.endswith("/jpeg"):
            return True
        last = self._last.get(key)
        if last is not None and log_ns - last < self.period_ns:
            return False
        self._last[key] = log_ns
        return True


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb foxglove", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_bus_args(parser, connect_timeout_s=0.0)
    parser.add_argument("--host", default="127.0.0.1",
                        help="address the WebSocket server binds (0.0.0.0: every interface)")
    parser.add_argument("--port", type=int, default=DEFAULT_PORTS["foxglove"],
                        help=f"WebSocket port, default {DEFAULT_PORTS['foxglove']} "
                             f"(Foxglove's; aeb label's is {DEFAULT_PORTS['label']}); 0: any "
                             "free")
    parser.add_argument("--keys", default="", help="only these keys (default: every key)")
    parser.add_argument("--max-fps", type=float, default=0.0,
                        help="at most this many camera frames per second (0: all)")
    parser.add_argument("--scale", type=float, default=1.0,
                        help="resize camera frames by this factor (0 < scale <= 1)")
    parser.add_argument("--fusion-config", default="",
                        help="fusion config whose corridor the scene draws")
    parser.add_argument("--duration", type=float, default=None)
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    import foxglove

    from aeb_radar_camera.common.config.loader import ConfigError
    from aeb_radar_camera.tools.recording.foxglove_views import Converter
    from aeb_radar_camera.tools.recording.recorder import Recorder, decision_settings, selection

    setup_logging("foxglove", args.log_level)
    stop = stop_event_on_signals()
    try:
        if args.max_fps < 0:
            raise ValueError("--max-fps must not be negative")
        converter = Converter(args.vehicle, decision_settings(args.fusion_config), args.scale)
        exprs = selection(args.keys, args.vehicle)
    except (ValueError, ConfigError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    context = foxglove.Context()
    try:
        server = foxglove.start_server(name="aeb", host=args.host, port=args.port,
                                       context=context)
    except RuntimeError as exc:
        if f"(os error {errno.EADDRINUSE})" in str(exc):
            print(f"error: {port_in_use('foxglove', args.host, args.port)}", file=sys.stderr)
        else:
            print(f"error: cannot start the WebSocket server on {args.host}:{args.port}: "
                  f"{exc}", file=sys.stderr)
        return 2
    bus = open_bus(args, "foxglove", stop)
    sink = FoxgloveSink(context)
    with bus:
        recorder = Recorder(bus, sink, exprs, converter, keep=FrameLimit(args.max_fps))
        recorder.start()
        token = bus.declare_health("foxglove", str(os.getpid()))
        print(f"Foxglove WebSocket on ws://{args.host}:{server.port} (Foxglove: Open "
              "connection, Foxglove WebSocket)", file=sys.stderr, flush=True)
        run_until(stop, args.duration)
        token.undeclare()
        recorder.stop()
    server.stop()
    n = sum(c.messages for c in sink.stats.topics.values())
    print(f"sent {n} messages on {len(sink.stats.topics)} channels", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
