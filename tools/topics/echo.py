"""`aeb echo KEY`: decoded messages of any key, as `ros2 topic echo` shows them.

    aeb echo radar/front/tracks                 # JSON lines, one per message
    aeb echo fusion_brake_cmd --table           # a short table (registry names work too)
    aeb echo 'fusion/*/brake_cmd' --count 5
    aeb echo '**' --table --duration 3 --connect tcp/192.168.10.1:7447

KEY: a registry name (`radar_tracks`), a key under aeb/<vehicle>/ (wildcards allowed) or a
full key; one no registry key matches is warned about, with the registry's nearest names.
A sample's message type comes from its encoding (`application/msgpack;aeb.<Type>`),
else from its key. JSON lines: {"key", "type", "rx_wall_ns", "msg"}; byte fields (JPEG)
show their length unless --bytes. Samples that do not decode are shown as such and
counted on stderr at the end. Exit codes: 0, 1 when nothing arrived before --timeout, 2
when the bus cannot be opened.
"""

import argparse
import queue
import shutil
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any

import msgspec

from aeb_radar_camera.common.clock import wall_ns
from aeb_radar_camera.common.log import setup_logging
from aeb_radar_camera.common.messages import DecodeError, decode
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.tools.bus import add_bus_args, non_negative, open_bus
from aeb_radar_camera.tools.topics.catalog import Catalog

Sample = tuple[bytes, str, str, int]       # payload, key, encoding, receipt wall ns
# After this long without a sample, say so (as `ros2 topic echo` says a topic does not
# appear to be published yet); every registry key publishes at least once a second.
NO_PUBLISHER_S = 3.0


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb echo", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("key", help="registry name, key or key expression")
    parser.add_argument("--table", action="store_true", help="a short table, one row each")
    parser.add_argument("--count", type=int, default=0, help="exit after N messages")
    parser.add_argument("--duration", type=non_negative, default=None,
                        help="exit after S seconds")
    parser.add_argument("--timeout", type=non_negative, default=None,
                        help="exit 1 when no message arrived within S seconds")
    parser.add_argument("--bytes", action="store_true",
                        help="print byte fields in full (base64) instead of their length")
    add_bus_args(parser)
    return parser.parse_args(argv)


def _shorten_bytes(value: Any) -> Any:
    if isinstance(value, bytes):
        return {"bytes": len(value)}
    if isinstance(value, dict):
        return {k: _shorten_bytes(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_shorten_bytes(v) for v in value]
    return value


def as_builtins(msg: msgspec.Struct, full_bytes: bool) -> Any:
    if full_bytes:
        return msgspec.to_builtins(msg)
    return _shorten_bytes(msgspec.to_builtins(msg, builtin_types=(bytes,)))


@dataclass(frozen=True)
class Decoded:
    """A sample and what it decoded to: `msg` is None when it did not (`error` says why)."""

    key: str
    rx_wall_ns: int
    size: int
    type_name: str | None
    msg: msgspec.Struct | None
    error: str = ""


def decode_sample(catalog: Catalog, sample: Sample) -> Decoded:
    payload, key, encoding, rx_wall = sample
    msg_type = catalog.type_of(key, encoding)
    if msg_type is None:
        return Decoded(key, rx_wall, len(payload), None, None,
                       f"no message type known for this key (encoding {encoding!r})")
    try:
        return Decoded(key, rx_wall, len(payload), msg_type.__name__, decode(payload, msg_type))
    except DecodeError as exc:
        return Decoded(key, rx_wall, len(payload), msg_type.__name__, None, str(exc))


def json_line(d: Decoded, full_bytes: bool) -> str:
    line: dict[str, Any] = {"key": d.key, "type": d.type_name, "rx_wall_ns": d.rx_wall_ns}
    if d.msg is None:
        line |= {"error": d.error, "size": d.size}
    else:
        line["msg"] = as_builtins(d.msg, full_bytes)
    return msgspec.json.encode(line).decode()


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, (list, tuple)):
        return f"[{len(value)}]"
    if isinstance(value, dict):
        return f"{{bytes {value['bytes']}}}" if set(value) == {"bytes"} else "{...}"
    return str(value)


def table_row(catalog: Catalog, d: Decoded, width: int | None = None) -> str:
    """time, key, seq, age, then the message's top-level fields (arrays as [length]),
    cut at `width` characters when given."""
    clock = time.strftime("%H:%M:%S", time.localtime(d.rx_wall_ns / 1e9)) + \
        f".{d.rx_wall_ns // 1_000_000 % 1000:03d}"
    head = f"{clock}  {catalog.relative(d.key):<28}"
    if d.msg is None:
        return f"{head} UNDECODABLE {d.size} B: {d.error}"[:width]
    fields = as_builtins(d.msg, False)
    header = fields.pop("header", None)
    if header is not None:
        age_ms = (d.rx_wall_ns - header["stamp_ns"]) / 1e6
        head += f" seq={header['seq']:<6} age={age_ms:7.1f}ms"
    body = " ".join(f"{k}={_cell(v)}" for k, v in fields.items())
    return f"{head} {body}"[:width]


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging("echo", args.log_level)
    catalog = Catalog(args.vehicle)
    expr = catalog.expression(args.key)
    samples: queue.Queue[Sample] = queue.Queue(maxsize=10_000)
    dropped = [0]
    lock = threading.Lock()

    def on_sample(payload: bytes, key: str, encoding: str, rx_mono: int) -> None:
        try:
            samples.put_nowait((payload, key, encoding, wall_ns()))
        except queue.Full:       # the terminal is slower than the bus: say so at the end
            with lock:
                dropped[0] += 1

    stop = stop_event_on_signals()
    bus = open_bus(args, "echo", stop)
    shown = undecodable = 0
    start = time.monotonic()
    # a table row fits the terminal; piped, it is whole
    width = shutil.get_terminal_size().columns if sys.stdout.isatty() else None
    said_silent = False
    with bus:
        bus.subscribe_expr(expr, on_sample)
        print(f"# {expr}", file=sys.stderr, flush=True)
        if not catalog.known(expr):
            close = catalog.suggest(args.key)
            print(f"# warning: {expr} is no key of the registry"
                  + (f"; did you mean {' or '.join(close)}?" if close else "")
                  + " (`aeb list` shows the keys being published)", file=sys.stderr, flush=True)
        while not stop.is_set():
            now = time.monotonic()
            if args.duration is not None and now - start >= args.duration:
                break
            if not said_silent and shown == 0 and now - start >= NO_PUBLISHER_S:
                said_silent = True
                print(f"# nothing on {expr} in {NO_PUBLISHER_S:g} s: no publisher yet; still "
                      "waiting", file=sys.stderr, flush=True)
            if args.timeout is not None and shown == 0 and now - start >= args.timeout:
                print(f"error: nothing on {expr} within {args.timeout:g} s", file=sys.stderr)
                return 1
            try:
                sample = samples.get(timeout=0.1)
            except queue.Empty:
                continue
            d = decode_sample(catalog, sample)
            undecodable += d.msg is None
            print(table_row(catalog, d, width) if args.table else json_line(d, args.bytes),
                  flush=True)
            shown += 1
            if args.count and shown >= args.count:
                break
    if undecodable or dropped[0]:
        print(f"# {shown} messages, {undecodable} undecodable, {dropped[0]} not shown "
              "(output too slow)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
