"""Thread-safe counters by reason, for rejected inputs and other events."""

import threading
from collections import Counter
from collections.abc import Mapping

# Counters are published saturated here: every message encodes them as msgpack int64, and
# a counter past it would make every later message fail to encode (Python's own ints do
# not overflow, so only the published copy is clamped).
MAX_COUNT = 2**63 - 1


def saturated(counts: Mapping[str, int]) -> dict[str, int]:
    """A copy of `counts` fit for a message: every value clamped to 0..MAX_COUNT."""
    return {k: min(MAX_COUNT, max(0, v)) for k, v in counts.items()}


class ReasonCounter:
    def __init__(self) -> None:
        self._counts: Counter[str] = Counter()
        self._lock = threading.Lock()

    def add(self, reason: str, n: int = 1) -> None:
        with self._lock:
            self._counts[reason] += n

    def get(self, reason: str) -> int:
        with self._lock:
            return self._counts[reason]

    def total(self) -> int:
        with self._lock:
            return sum(self._counts.values())

    def snapshot(self) -> dict[str, int]:
        with self._lock:
            return dict(self._counts)
