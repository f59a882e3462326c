"""`aeb list`: the keys being published on a vehicle's bus, as `ros2 topic list -t` lists
topics: each key with its message type, who publishes it, and its rate.

    aeb list                                  # every key heard in 2 s
    aeb list --all                            # and the registry's keys nobody published
    aeb list --duration 5 --connect tcp/192.168.10.1:7447
    aeb list --json

Zenoh has no registry of publishers to ask (a router's admin space is off in the shipped
configs, and access control would refuse it), so the keys are those heard within
`--duration` (default 2 s: every key of the registry is published at least once a
second). The type comes from each sample's encoding (else the registry), the publishers
from the messages' `header.source` (the publishing service instance), the rate from the
arrivals heard. Exit codes: 0, 1 when nothing was heard, 2 when the bus cannot be opened.
"""

import argparse
import json
import sys
import threading
from dataclasses import dataclass, field

import msgspec

from aeb_radar_camera.common.clock import mono_ns
from aeb_radar_camera.common.log import setup_logging
from aeb_radar_camera.common.messages import Header
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.tools.bus import add_bus_args, non_negative, open_bus
from aeb_radar_camera.tools.topics.catalog import Catalog


class _Stamped(msgspec.Struct):
    header: Header       # the rest of the message is skipped, not decoded


_stamped = msgspec.msgpack.Decoder(_Stamped)


@dataclass
class Heard:
    """What was heard of one key."""

    type_name: str = "-"
    messages: int = 0
    first_ns: int = 0
    last_ns: int = 0
    publishers: set[str] = field(default_factory=set)

    @property
    def rate_hz(self) -> float | None:
        """Over the arrivals heard; None before two."""
        if self.messages < 2 or self.last_ns <= self.first_ns:
            return None
        return (self.messages - 1) * 1e9 / (self.last_ns - self.first_ns)


class Listing:
    """Every key heard (fed from Zenoh's threads; `rx_mono` in ns)."""

    def __init__(self, catalog: Catalog) -> None:
        self.catalog = catalog
        self.keys: dict[str, Heard] = {}
        self._lock = threading.Lock()

    def on_sample(self, payload: bytes, key: str, encoding: str, rx_mono: int) -> None:
        msg_type = self.catalog.type_of(key, encoding)
        try:
            source = _stamped.decode(payload).header.source
        except (msgspec.DecodeError, msgspec.ValidationError):
            source = ""
        with self._lock:
            heard = self.keys.get(key)
            if heard is None:
                heard = self.keys[key] = Heard(first_ns=rx_mono)
            heard.messages += 1
            heard.last_ns = rx_mono
            if msg_type is not None:
                heard.type_name = msg_type.__name__
            if source:
                heard.publishers.add(source)

    def rows(self, every: bool) -> list[dict[str, object]]:
        """One row per key heard, sorted; with `every`, also each registry key not heard."""
        with self._lock:
            heard = dict(self.keys)
        rows: list[dict[str, object]] = []
        for key, h in sorted(heard.items()):
            spec = self.catalog.spec_of(key)
            rows.append({"key": self.catalog.relative(key), "type": h.type_name,
                         "publishers": sorted(h.publishers), "messages": h.messages,
                         "rate_hz": h.rate_hz, "nominal_hz": spec.rate_hz if spec else None,
                         "nominal_is_minimum": bool(spec and spec.rate_is_minimum)})
        if every:
            seen = {self.catalog.spec_of(k) for k in heard}
            for spec in self.catalog.keys:
                if spec not in seen:
                    assert spec.msg_type is not None
                    rows.append({"key": spec.pattern, "type": spec.msg_type.__name__,
                                 "publishers": [], "messages": 0, "rate_hz": None,
                                 "nominal_hz": spec.rate_hz,
                                 "nominal_is_minimum": spec.rate_is_minimum})
        return rows


def render(rows: list[dict[str, object]], duration_s: float) -> str:
    lines = [f"{'key':<30} {'type':<16} {'publishers':<24} {'msgs':>6} {'rate_hz':>8} "
             f"{'nominal':>8}"]
    for r in rows:
        rate = r["rate_hz"]
        nominal = r["nominal_hz"]
        shown_rate = f"{rate:8.2f}" if isinstance(rate, float) else f"{'-':>8}"
        shown_nominal = ((">=" if r["nominal_is_minimum"] else "") + f"{nominal:.4g}"
                         if isinstance(nominal, float) else "-")
        publishers = r["publishers"]
        assert isinstance(publishers, list)
        who = ", ".join(publishers) if publishers else (
            "(none heard)" if r["messages"] == 0 else "-")
        lines.append(f"{r['key']!s:<30} {r['type']!s:<16} {who:<24} {r['messages']!s:>6} "
                     f"{shown_rate} {shown_nominal:>8}")
    heard = sum(1 for r in rows if r["messages"])
    lines.append(f"{heard} key(s) heard in {duration_s:g} s")
    return "\n".join(lines)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb list", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=non_negative, default=2.0,
                        help="listen this long (s), default 2")
    parser.add_argument("--all", action="store_true",
                        help="also the registry's keys nobody published meanwhile")
    parser.add_argument("--json", action="store_true", help="one JSON object")
    add_bus_args(parser)
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging("list", args.log_level)
    catalog = Catalog(args.vehicle)
    listing = Listing(catalog)
    stop = stop_event_on_signals()
    bus = open_bus(args, "list", stop)
    with bus:
        bus.subscribe_expr(catalog.expression("**"), listing.on_sample)
        started = mono_ns()
        stop.wait(args.duration)
        listened_s = round((mono_ns() - started) / 1e9, 1)
    rows = listing.rows(args.all)
    if args.json:
        print(json.dumps({"vehicle": args.vehicle, "listened_s": listened_s, "keys": rows}))
    else:
        print(render(rows, listened_s))
    return 0 if listing.keys else 1


if __name__ == "__main__":
    sys.exit(main())
