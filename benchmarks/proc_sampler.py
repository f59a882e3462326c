"""CPU time and resident memory of processes, read from /proc (Linux)."""

import os
import threading
import time
from dataclasses import dataclass, field

_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")
_PAGE = os.sysconf("SC_PAGE_SIZE")


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of every thread of `pid`. Raises OSError when it is gone."""
    with open(f"/proc/{pid}/stat", encoding="ascii") as f:
        # The command name (field 2) may hold spaces: split after its closing parenthesis.
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) * _TICK_S


def rss_bytes(pid: int) -> int:
    """Resident set size of `pid`. Raises OSError when it is gone."""
    with open(f"/proc/{pid}/statm", encoding="ascii") as f:
        return int(f.read().split()[1]) * _PAGE


@dataclass
class Usage:
    cpu_s: float = 0.0           # CPU seconds used over the window
    wall_s: float = 0.0
    rss_max: int = 0
    rss_samples: list[int] = field(default_factory=list)

    @property
    def cpu_pct(self) -> float:
        """Share of one core, in percent."""
        return 100.0 * self.cpu_s / self.wall_s if self.wall_s else 0.0


class ProcSampler:
    """Samples named processes every `period_s` between `start()` and `stop()`."""

    def __init__(self, pids: dict[str, int], period_s: float = 0.25) -> None:
        self.pids = pids
        self.period_s = period_s
        self.usage = {name: Usage() for name in pids}
        self._cpu0: dict[str, float] = {}
        self._t0 = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="proc-sampler", daemon=True)

    def start(self) -> "ProcSampler":
        self._t0 = time.monotonic()
        self._cpu0 = {name: cpu_seconds(pid) for name, pid in self.pids.items()}
        self._thread.start()
        return self

    def _sample_rss(self) -> None:
        for name, pid in self.pids.items():
            try:
                rss = rss_bytes(pid)
            except OSError:
                continue
            u = self.usage[name]
            u.rss_samples.append(rss)
            u.rss_max = max(u.rss_max, rss)

    def _loop(self) -> None:
        while not self._stop.wait(self.period_s):
            self._sample_rss()

    def stop(self) -> dict[str, Usage]:
        """Raises OSError when a sampled process died during the window."""
        self._stop.set()
        self._thread.join()
        self._sample_rss()
        wall = time.monotonic() - self._t0
        for name, pid in self.pids.items():
            u = self.usage[name]
            u.cpu_s = cpu_seconds(pid) - self._cpu0[name]
            u.wall_s = wall
        return self.usage
