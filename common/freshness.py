"""Is each input alive (newest sample young enough) and on rate (arrivals near nominal)?

Pure: every call takes the current monotonic time in nanoseconds.
"""

from collections import deque
from dataclasses import dataclass
from typing import Any

from aeb_radar_camera.common.keys import KeySpec


@dataclass(frozen=True)
class InputHealth:
    name: str
    alive: bool
    on_rate: bool
    age_s: float | None      # None before the first sample
    rate_hz: float           # measured over the window
    nominal_rate_hz: float | None


class Freshness:
    """One input. `alive` iff the newest sample is at most `max_age_s` old. `on_rate` iff
    alive and the rate measured over `window_s` is within `tolerance` (fraction) of nominal
    (with `rate_is_minimum`: not below nominal by more than that, however far above).
    """

    def __init__(
        self,
        name: str,
        max_age_s: float,
        nominal_rate_hz: float | None = None,
        tolerance: float = 0.3,
        window_s: float = 2.0,
        rate_is_minimum: bool = False,
    ) -> None:
        if max_age_s <= 0:
            raise ValueError(f"{name}: max_age_s must be positive")
        self.name = name
        self.max_age_ns = int(max_age_s * 1e9)
        self.nominal_rate_hz = nominal_rate_hz
        self.tolerance = tolerance
        self.rate_is_minimum = rate_is_minimum
        self.window_ns = int(window_s * 1e9)
        self._arrivals: deque[int] = deque()
        self.count = 0

    @classmethod
    def from_spec(cls, spec: KeySpec[Any], name: str | None = None, **kw: Any) -> "Freshness":
        if spec.max_age_s is None:
            raise ValueError(f"key {spec.name!r} has no max age")
        kw.setdefault("rate_is_minimum", spec.rate_is_minimum)
        return cls(name or spec.name, spec.max_age_s, spec.rate_hz, **kw)

    def observe(self, now_ns: int) -> None:
        self.count += 1
        self._arrivals.append(now_ns)
        self._trim(now_ns)

    def _trim(self, now_ns: int) -> None:
        while self._arrivals and now_ns - self._arrivals[0] > self.window_ns:
            self._arrivals.popleft()

    def last_ns(self) -> int | None:
        return self._arrivals[-1] if self._arrivals else None

    def age_s(self, now_ns: int) -> float | None:
        last = self.last_ns()
        return None if last is None else (now_ns - last) / 1e9

    def alive(self, now_ns: int) -> bool:
        last = self.last_ns()
        return last is not None and now_ns - last <= self.max_age_ns

    def rate_hz(self, now_ns: int) -> float:
        """Arrivals per second over the window: (n - 1) intervals over the time from the
        oldest arrival kept to now, so that it is right before the window has filled and
        falls towards 0 as an input goes silent."""
        self._trim(now_ns)
        if len(self._arrivals) < 2:
            return 0.0
        span_ns = min(self.window_ns, now_ns - self._arrivals[0])
        return (len(self._arrivals) - 1) / (span_ns / 1e9)

    def health(self, now_ns: int) -> InputHealth:
        alive = self.alive(now_ns)
        rate = self.rate_hz(now_ns)
        if self.nominal_rate_hz is None:
            on_rate = alive
        else:
            below = self.nominal_rate_hz - rate
            off = below if self.rate_is_minimum else abs(below)
            on_rate = alive and off <= self.tolerance * self.nominal_rate_hz
        return InputHealth(self.name, alive, on_rate, self.age_s(now_ns), rate,
                           self.nominal_rate_hz)


class FreshnessTracker:
    """Several named inputs."""

    def __init__(self) -> None:
        self.inputs: dict[str, Freshness] = {}

    def add(self, freshness: Freshness) -> Freshness:
        self.inputs[freshness.name] = freshness
        return freshness

    def observe(self, name: str, now_ns: int) -> None:
        self.inputs[name].observe(now_ns)

    def snapshot(self, now_ns: int) -> dict[str, InputHealth]:
        return {name: f.health(now_ns) for name, f in self.inputs.items()}

    def all_alive(self, now_ns: int) -> bool:
        return all(f.alive(now_ns) for f in self.inputs.values())
