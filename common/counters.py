"""Thread-safe counters by reason, for rejected inputs and other events."""

import threading
from collections import Counter
from collections.abc import Mapping, MutableMapping

# Counters saturate here: every message encodes them as msgpack int64, and a counter that
# passed it would make every later message fail to encode.
MAX_COUNT = 2**63 - 1


def saturating_add(counts: MutableMapping[str, int], key: str, n: int = 1) -> None:
    """`counts[key] += n`, stopping at MAX_COUNT (a saturated counter stays there)."""
    counts[key] = min(MAX_COUNT, counts.get(key, 0) + n)


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
