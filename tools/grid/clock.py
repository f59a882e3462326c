"""The lockstep loop's simulated clock: events in time order (ties in the order they
were scheduled), nothing on the host's clocks, so a run is the same on every machine and
at any load.

The services' cores take monotonic and wall times in nanoseconds; on this clock both run
from fixed origins (`MONO0_NS`, `WALL0_NS`) at the simulated time, so the same scenario
gives the same stamps in every run.
"""

import heapq
from collections.abc import Callable
from itertools import count

MONO0_NS = 1_000_000_000_000               # the monotonic clock at the loop's start
WALL0_NS = 1_800_000_000_000_000_000       # the wall clock then (a date in 2027)


class Events:
    """A queue of callbacks at simulated times. `now_ns` is the time since the loop's
    start; `mono_ns` / `wall_ns` the services' clocks at that time."""

    def __init__(self) -> None:
        self.now_ns = 0
        self._queue: list[tuple[int, int, Callable[[int], None]]] = []
        self._order = count()

    def at(self, t_ns: int, callback: Callable[[int], None]) -> None:
        """`callback(t_ns)` at `t_ns` (now, if that has passed)."""
        heapq.heappush(self._queue, (max(t_ns, self.now_ns), next(self._order), callback))

    def run_until(self, done: Callable[[], bool], limit_ns: int) -> bool:
        """Run the events in time order until `done()` (checked after each) or the next
        one would fall after `limit_ns`; whether `done()` came true."""
        while self._queue and not done():
            t, _, callback = self._queue[0]
            if t > limit_ns:
                return False
            heapq.heappop(self._queue)
            self.now_ns = t
            callback(t)
        return done()

    def mono_ns(self, t_ns: int | None = None) -> int:
        return MONO0_NS + (self.now_ns if t_ns is None else t_ns)

    def wall_ns(self, t_ns: int | None = None) -> int:
        return WALL0_NS + (self.now_ns if t_ns is None else t_ns)
