"""The two clocks every message uses.

`wall_ns` stamps when data was measured (comparable across hosts when their clocks are
synchronised); `mono_ns` stamps publish times for same-host latency (never jumps).
Cores never call these: the shells pass the current time in.
"""

import time

wall_ns = time.time_ns
mono_ns = time.monotonic_ns

NS_PER_S = 1_000_000_000
NS_PER_MS = 1_000_000


def ns_to_s(ns: int) -> float:
    return ns / NS_PER_S


def s_to_ns(s: float) -> int:
    return round(s * NS_PER_S)
