"""Publish rate of a key from its arrival (or stamp) times, as `ros2 topic hz` reports
it: the mean rate over a window of the last N periods, and the min, max and standard
deviation of those periods. Pure: times in, numbers out."""

import math
from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True)
class RateReport:
    count: int                  # messages seen in all
    window: int                 # periods in the window
    rate_hz: float              # 1 / mean period; 0 before two messages
    min_s: float
    max_s: float
    std_s: float                # population standard deviation of the periods
    backwards: int              # times that went backwards (stamps out of order), skipped


class PeriodStats:
    """The last `window` periods between consecutive times (ns)."""

    def __init__(self, window: int = 100) -> None:
        if window < 1:
            raise ValueError("window must be at least 1")
        self._periods: deque[int] = deque(maxlen=window)
        self._last: int | None = None
        self.count = 0
        self.backwards = 0

    def add(self, t_ns: int) -> None:
        self.count += 1
        if self._last is not None:
            if t_ns < self._last:
                self.backwards += 1
                return
            self._periods.append(t_ns - self._last)
        self._last = t_ns

    def report(self) -> RateReport:
        n = len(self._periods)
        if n == 0:
            return RateReport(self.count, 0, 0.0, math.nan, math.nan, math.nan, self.backwards)
        mean = sum(self._periods) / n
        var = sum((p - mean) ** 2 for p in self._periods) / n
        return RateReport(self.count, n, 1e9 / mean if mean > 0 else math.inf,
                          min(self._periods) / 1e9, max(self._periods) / 1e9,
                          math.sqrt(var) / 1e9, self.backwards)
