"""What `aeb monitor` knows about the bus, pure: per-key rates and latencies, the newest
message of each kind, and each service's liveliness. Every call takes the receipt or
current time in; nothing here reads a clock or touches Zenoh.

Latencies from header stamps:
- `age`: receipt wall time minus `header.stamp_ns` (when the data was measured). Across
  hosts it is only as good as their clock synchronisation.
- `transport`: receipt monotonic time minus `header.pub_mono_ns` (publish to receipt).
  Monotonic clocks are per host, so it is only kept when the monitor runs on the
  publishers' host (`same_host`).
"""

from collections import deque
from dataclasses import dataclass, field
from typing import Any

from aeb_radar_camera.common.freshness import Freshness
from aeb_radar_camera.common.keys import KeySpec

WINDOW_S = 5.0
_NS = 1_000_000_000


@dataclass
class KeyStats:
    spec_name: str
    freshness: Freshness                                            # arrivals, rate, alive
    ages_ms: deque[tuple[int, float]] = field(default_factory=deque)
    transport_ms: deque[tuple[int, float]] = field(default_factory=deque)
    count: int = 0
    last_seq: int | None = None
    seq_gaps: int = 0          # messages missed, from header.seq jumps

    def trim(self, now_ns: int) -> None:
        edge = now_ns - int(WINDOW_S * _NS)
        for q in (self.ages_ms, self.transport_ms):
            while q and q[0][0] < edge:
                q.popleft()


@dataclass(frozen=True)
class KeyView:
    key: str
    spec_name: str
    count: int
    rate_hz: float
    nominal_hz: float | None
    alive: bool                  # newest sample within the registry's max age
    on_rate: bool                # alive and within 30% of the nominal rate (not below it
                                 # by more, for a key whose rate is a minimum)
    last_age_s: float            # since the last receipt
    age_p50_ms: float | None
    age_p99_ms: float | None
    transport_p50_ms: float | None
    transport_p99_ms: float | None
    seq_gaps: int


@dataclass(frozen=True)
class HealthView:
    service: str
    instance: str
    alive: bool
    since_s: float               # in the current state for this long


def _percentiles(values: deque[tuple[int, float]]) -> tuple[float | None, float | None]:
    if not values:
        return None, None
    import numpy as np  # here: `aeb monitor --help` needs no extra installed

    arr = np.fromiter((v for _, v in values), float, len(values))
    return float(np.percentile(arr, 50)), float(np.percentile(arr, 99))


class MonitorState:
    """Aggregates what the monitor receives. Thread-safety is the caller's (the shell
    holds one lock around observe/snapshot)."""

    def __init__(self, same_host: bool) -> None:
        self.same_host = same_host
        self.keys: dict[str, KeyStats] = {}
        self.latest: dict[str, tuple[Any, int]] = {}    # key -> (message, receipt mono ns)
        self.health: dict[tuple[str, str], tuple[bool, int]] = {}
        self.decode_errors: dict[str, int] = {}

    def observe(self, spec: KeySpec[Any], key: str, msg: Any, rx_mono_ns: int,
                rx_wall_ns: int) -> None:
        stats = self.keys.get(key)
        if stats is None:
            stats = self.keys[key] = KeyStats(spec.name,
                                              Freshness.from_spec(spec, window_s=WINDOW_S))
        stats.count += 1
        stats.freshness.observe(rx_mono_ns)
        header = getattr(msg, "header", None)
        if header is not None:
            stats.ages_ms.append((rx_mono_ns, (rx_wall_ns - header.stamp_ns) / 1e6))
            if self.same_host:
                stats.transport_ms.append((rx_mono_ns, (rx_mono_ns - header.pub_mono_ns) / 1e6))
            if stats.last_seq is not None and header.seq > stats.last_seq + 1:
                stats.seq_gaps += header.seq - stats.last_seq - 1
            stats.last_seq = header.seq
        stats.trim(rx_mono_ns)
        self.latest[key] = (msg, rx_mono_ns)

    def on_health(self, service: str, instance: str, alive: bool, now_ns: int) -> None:
        prev = self.health.get((service, instance))
        if prev is None or prev[0] != alive:
            self.health[(service, instance)] = (alive, now_ns)

    def newest(self, spec: KeySpec[Any]) -> list[tuple[str, Any, int]]:
        """(key, message, receipt mono ns) for every key of `spec`, sorted by key."""
        out = []
        for key, (msg, rx) in sorted(self.latest.items()):
            stats = self.keys.get(key)
            if stats is not None and stats.spec_name == spec.name:
                out.append((key, msg, rx))
        return out

    def key_views(self, now_mono_ns: int) -> list[KeyView]:
        views = []
        for key, stats in sorted(self.keys.items()):
            stats.trim(now_mono_ns)
            h = stats.freshness.health(now_mono_ns)
            last = self.latest[key][1]
            a50, a99 = _percentiles(stats.ages_ms)
            t50, t99 = _percentiles(stats.transport_ms)
            views.append(KeyView(key, stats.spec_name, stats.count, h.rate_hz,
                                 h.nominal_rate_hz, h.alive, h.on_rate,
                                 (now_mono_ns - last) / _NS, a50, a99, t50, t99,
                                 stats.seq_gaps))
        return views

    def health_views(self, now_mono_ns: int) -> list[HealthView]:
        return [HealthView(s, i, alive, (now_mono_ns - since) / _NS)
                for (s, i), (alive, since) in sorted(self.health.items())]

