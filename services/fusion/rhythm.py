"""When is the next radar cycle due? (pure: arrival times in, no clocks)

With `frames.decode = "before_radar"`, fusion decodes only the camera frames a radar
cycle can use. A cycle uses the newest frame (or the one nearest its stamp, which in
practice is the newest: frames take longer to arrive than radar cycles); at 30 fps and a
radar cycle of about 74 ms, two of every three frames are overtaken by a newer one
before the next cycle arrives and would be decoded for nothing. So, while the radar's
rhythm is steady, a frame waits undecoded until `lead` before the next cycle is due,
and only the newest waiting one is then decoded; frames arriving after that point are
decoded on arrival. When the rhythm is unknown, irregular, or the radar is late or
silent, every frame is decoded on arrival (as with `every_frame`).
"""

import statistics
from collections import deque

_HISTORY = 8            # radar arrival intervals kept
_MIN_INTERVALS = 4      # before the rhythm is trusted
_MAX_SPREAD = 0.25      # max - min interval, as a share of the median, to count as steady


class RadarRhythm:
    """Radar cycle arrival times (monotonic ns) -> when the next one is due.

    `on_cycle` is called from the radar callback; `decode_at` from decoder threads.
    The state they share is one tuple, replaced whole (atomic under the GIL).
    """

    def __init__(self) -> None:
        self._arrivals: deque[int] = deque(maxlen=_HISTORY + 1)
        self._state: tuple[int, int] | None = None     # (last arrival, period) when steady

    def on_cycle(self, rx_mono_ns: int) -> None:
        arrivals = self._arrivals
        if arrivals and rx_mono_ns <= arrivals[-1]:
            return                                    # a duplicate or a clock step: ignore
        arrivals.append(rx_mono_ns)
        intervals = [b - a for a, b in zip(arrivals, list(arrivals)[1:], strict=False)]
        if len(intervals) < _MIN_INTERVALS:
            self._state = None
            return
        period = int(statistics.median(intervals))
        steady = max(intervals) - min(intervals) <= _MAX_SPREAD * period
        self._state = (rx_mono_ns, period) if steady and period > 0 else None

    @property
    def period_ns(self) -> int | None:
        """The radar cycle period while the rhythm is steady, else None."""
        state = self._state
        return None if state is None else state[1]

    def decode_at(self, now_mono_ns: int, lead_ns: int) -> int | None:
        """When a frame waiting now should be decoded: None for at once (rhythm unknown,
        next cycle due within `lead_ns`, late or missing), else a monotonic time."""
        state = self._state
        if state is None:
            return None
        last, period = state
        due = last + period - lead_ns
        if now_mono_ns >= due:
            return None
        return due
