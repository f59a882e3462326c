"""`aeb hz KEY`: the publish rate of every key matching KEY, as `ros2 topic hz` reports
it: mean rate over a window of the last N periods, and the min, max and standard
deviation of the period.

    aeb hz radar/front/tracks                   # a row per key, every second
    aeb hz '**' --duration 5                    # every key, one table after 5 s
    aeb hz fusion_brake_cmd --clock stamp       # periods of the messages' own stamps

KEY as for `aeb echo`. `--clock receipt` (default) times arrivals here (the network's
jitter included); `--clock stamp` uses each message's `header.stamp_ns`, when its data
was measured (the radar's own cycle, free of transport jitter; samples without a header
are left out and counted). Exit codes: 0, 1 when nothing arrived, 2 when the bus cannot
be opened.
"""

import argparse
import json
import math
import sys
import threading
import time
from dataclasses import asdict

import msgspec

from aeb_radar_camera.common.clock import mono_ns
from aeb_radar_camera.common.log import setup_logging
from aeb_radar_camera.common.messages import Header
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.tools.bus import add_bus_args, non_negative, open_bus, positive
from aeb_radar_camera.tools.topics.catalog import Catalog
from aeb_radar_camera.tools.topics.rates import PeriodStats, RateReport


class _Stamped(msgspec.Struct):
    """Any message's header alone (the other fields are skipped, not decoded)."""

    header: Header


_stamped = msgspec.msgpack.Decoder(_Stamped)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="aeb hz", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("key", help="registry name, key or key expression")
    parser.add_argument("--window", type=int, default=100,
                        help="periods per key the statistics cover (default 100)")
    parser.add_argument("--clock", choices=["receipt", "stamp"], default="receipt")
    parser.add_argument("--interval", type=positive, default=1.0, help="report period (s)")
    parser.add_argument("--duration", type=non_negative, default=None,
                        help="exit after S seconds, with one last report")
    parser.add_argument("--json", action="store_true", help="JSON lines instead of a table")
    add_bus_args(parser)
    return parser.parse_args(argv)


class Rates:
    """Per-key period statistics, fed from Zenoh's threads."""

    def __init__(self, window: int, stamp_clock: bool) -> None:
        self.window = window
        self.stamp_clock = stamp_clock
        self.keys: dict[str, PeriodStats] = {}
        self.unstamped = 0
        self._lock = threading.Lock()

    def on_sample(self, payload: bytes, key: str, encoding: str, rx_mono: int) -> None:
        t = rx_mono
        if self.stamp_clock:
            try:
                t = _stamped.decode(payload).header.stamp_ns
            except (msgspec.DecodeError, msgspec.ValidationError):
                with self._lock:
                    self.unstamped += 1
                return
        with self._lock:
            stats = self.keys.get(key)
            if stats is None:
                stats = self.keys[key] = PeriodStats(self.window)
            stats.add(t)

    def reports(self) -> dict[str, RateReport]:
        with self._lock:
            return {k: s.report() for k, s in sorted(self.keys.items())}


def _ms(seconds: float) -> str:
    return "-" if math.isnan(seconds) else f"{seconds * 1e3:8.2f}"


def render(catalog: Catalog, reports: dict[str, RateReport]) -> str:
    lines = [f"{'key':<32} {'rate_hz':>8} {'nominal':>8} {'min_ms':>8} {'max_ms':>8} "
             f"{'std_ms':>8} {'window':>6} {'msgs':>7}"]
    for key, r in reports.items():
        spec = catalog.spec_of(key)
        nominal = f"{spec.rate_hz:8.2f}" if spec is not None and spec.rate_hz else f"{'-':>8}"
        lines.append(f"{catalog.relative(key):<32} {r.rate_hz:8.2f} {nominal} {_ms(r.min_s)} "
                     f"{_ms(r.max_s)} {_ms(r.std_s)} {r.window:6d} {r.count:7d}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.window < 1 or args.interval <= 0:
        print("error: --window must be at least 1 and --interval positive", file=sys.stderr)
        return 2
    setup_logging("hz", args.log_level)
    catalog = Catalog(args.vehicle)
    expr = catalog.expression(args.key)
    rates = Rates(args.window, args.clock == "stamp")
    stop = stop_event_on_signals()
    bus = open_bus(args, "hz", stop)
    end = None if args.duration is None else time.monotonic() + args.duration
    with bus:
        bus.subscribe_expr(expr, rates.on_sample)
        print(f"# {expr}, clock {args.clock}, window {args.window}", file=sys.stderr,
              flush=True)
        while not stop.is_set():
            left = args.interval if end is None else min(args.interval, end - time.monotonic())
            if left > 0 and stop.wait(left):
                break
            last = end is not None and time.monotonic() >= end
            if end is None or last:
                show(catalog, rates.reports(), args.json)
            if last:
                break
    if rates.unstamped:
        print(f"# {rates.unstamped} samples without a header (left out)", file=sys.stderr)
    return 0 if rates.keys else 1


def show(catalog: Catalog, reports: dict[str, RateReport], as_json: bool) -> None:
    if as_json:
        print(json.dumps({"mono_ns": mono_ns(), "keys": {
            k: {n: (None if isinstance(v, float) and math.isnan(v) else v)
                for n, v in asdict(r).items()} for k, r in reports.items()}}), flush=True)
    else:
        print(render(catalog, reports) + "\n", flush=True)


if __name__ == "__main__":
    sys.exit(main())
