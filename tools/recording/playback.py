"""The replay's clock under a person's control: pause, step one message, rate up and down
(the keys of `ros2 bag play`), as `aeb replay` applies them (tools/recording/keyboard.py
reads the keys).

Time is anchored: recorded time `rec_ns` is due at `anchor_mono + (rec_ns - anchor_rec)
/ rate` and stamped `anchor_wall + (rec_ns - anchor_rec) / rate`. Every change (pause,
resume, step, a new rate) re-anchors at the recorded time reached, so a message keeps
the spacing to its neighbours that it had at the rate it plays at, and its age when it
goes out is its recorded age. Thread-safe: the keyboard's thread changes it while the
replay's thread waits in `wait_due`. Clocks are arguments, for the tests.
"""

import threading
from collections.abc import Callable
from dataclasses import dataclass

RATE_STEP = 1.1           # up / down: 10% faster or slower, as ros2 bag play
MIN_RATE, MAX_RATE = 0.01, 100.0


@dataclass(frozen=True)
class TimeMap:
    """Recorded wall time -> replay wall time (`rate`; `fast`: each message keeps its
    recorded age at the moment it is published)."""

    rec0_ns: int
    now0_ns: int
    rate: float
    fast: bool

    def wall(self, t_ns: int, log_ns: int, now_ns: int) -> int:
        if self.fast:
            return t_ns + (now_ns - log_ns)
        return self.now0_ns + round((t_ns - self.rec0_ns) / self.rate)


class Playback:
    """`rate`: recorded seconds per second (ignored with `fast`: every message at once,
    publishers waiting on their subscribers). `mono`, `wall`: the clocks (ns)."""

    def __init__(self, rate: float, fast: bool, mono: Callable[[], int],
                 wall: Callable[[], int]) -> None:
        if rate <= 0:
            raise ValueError("the rate must be positive")
        self.rate = rate
        self.fast = fast
        self.paused = False
        self._mono = mono
        self._wall = wall
        self._steps = 0              # messages to let out while paused
        self._cond = threading.Condition()
        self._rec = self._anchor_mono = self._anchor_wall = 0
        self._origin = 0             # where the pass began
        self._position = 0           # the recorded time of the last message let out
        self.released = 0            # messages let out

    # ---- the replay's side ---------------------------------------------------------------

    def start(self, rec_ns: int) -> None:
        """A pass begins at recorded time `rec_ns`, due now."""
        with self._cond:
            self._origin = self._position = rec_ns
            self._anchor(rec_ns)

    def due_mono(self, rec_ns: int) -> int:
        """When the message recorded at `rec_ns` is due while playing (monotonic ns)."""
        with self._cond:
            return self._due(rec_ns)

    def time_map(self) -> TimeMap:
        """The stamps' mapping for the message about to go out."""
        with self._cond:
            return TimeMap(self._rec, self._anchor_wall, self.rate, self.fast)

    def wait_due(self, rec_ns: int, stop: threading.Event) -> bool:
        """Until the message recorded at `rec_ns` may go out: its time at the rate when
        playing, a step when paused. False when `stop` was set first."""
        with self._cond:
            while not stop.is_set():
                if self.paused:
                    if self._steps:
                        self._steps -= 1
                        self._position = rec_ns
                        self.released += 1
                        self._anchor(rec_ns)
                        return True
                    self._cond.wait(0.1)
                    continue
                wait_ns = 0 if self.fast else self._due(rec_ns) - self._mono()
                if wait_ns <= 0:
                    self._position = rec_ns
                    self.released += 1
                    return True
                self._cond.wait(min(wait_ns / 1e9, 0.1))
            return False

    # ---- the keyboard's side -------------------------------------------------------------

    def toggle_pause(self) -> bool:
        """Pause, or resume from where it stands; returns whether it is paused."""
        with self._cond:
            self.paused = not self.paused
            self._steps = 0
            if not self.paused:
                self._anchor(self._position)
            self._cond.notify_all()
            return self.paused

    def step(self) -> None:
        """One message out, then paused (pauses first when playing)."""
        with self._cond:
            self.paused = True
            self._steps += 1
            self._cond.notify_all()

    def faster(self) -> float:
        return self.set_rate(self.rate * RATE_STEP)

    def slower(self) -> float:
        return self.set_rate(self.rate / RATE_STEP)

    def set_rate(self, rate: float) -> float:
        """Another rate from the recorded time reached; returns it (bounded)."""
        with self._cond:
            now_rec = self._position if self.paused else self._reached()
            self.rate = min(MAX_RATE, max(MIN_RATE, rate))
            self._anchor(now_rec)
            self._cond.notify_all()
            return self.rate

    @property
    def position_ns(self) -> int:
        """The recorded time of the last message let out."""
        with self._cond:
            return self._position

    @property
    def into_pass_s(self) -> float:
        """How far into the pass the last message out was, in recorded seconds."""
        with self._cond:
            return (self._position - self._origin) / 1e9

    # ---- inside the lock -----------------------------------------------------------------

    def _anchor(self, rec_ns: int) -> None:
        self._rec = rec_ns
        self._anchor_mono = self._mono()
        self._anchor_wall = self._wall()

    def _due(self, rec_ns: int) -> int:
        return self._anchor_mono + round((rec_ns - self._rec) / self.rate)

    def _reached(self) -> int:
        """The recorded time playing has reached now (never behind the last message)."""
        return max(self._position,
                   self._rec + round((self._mono() - self._anchor_mono) * self.rate))
