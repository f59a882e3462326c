"""CPU time and resident memory of processes, read from /proc (Linux)."""

import os
import threading
import time
from dataclasses import dataclass, field

_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of every thread of `pid`. Raises OSError when it is gone."""
    with open(f"/proc/{pid}/stat", encoding="ascii") as f:
        # The command name (field 2) may hold spaces: split after its closing parenthesis.
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) * _TICK_S


@dataclass(frozen=True)
class Memory:
    """Bytes. `rss` counts shared pages (libraries, Zenoh's shared-memory pool) in full in
    every process that maps them; `pss` shares them out; `shmem` is the shared-memory part
    of `rss`."""

    rss: int
    pss: int
    anon: int
    shmem: int


def memory(pid: int) -> Memory:
    """Resident memory of `pid` from smaps_rollup. Raises OSError when it is gone."""
    values: dict[str, int] = {}
    with open(f"/proc/{pid}/smaps_rollup", encoding="ascii") as f:
        for line in f:
            parts = line.split()
            if len(parts) == 3 and parts[2] == "kB":
                values[parts[0].rstrip(":")] = int(parts[1]) * 1024
    with open(f"/proc/{pid}/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("RssShmem:"):
                values["RssShmem"] = int(line.split()[1]) * 1024
    return Memory(values.get("Rss", 0), values.get("Pss", 0), values.get("Anonymous", 0),
                  values.get("RssShmem", 0))


@dataclass
class Usage:
    cpu_s: float = 0.0           # CPU seconds used over the window
    wall_s: float = 0.0
    peak: Memory = Memory(0, 0, 0, 0)   # the sample with the largest RSS
    samples: list[Memory] = field(default_factory=list)

    @property
    def rss_max(self) -> int:
        return self.peak.rss

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
                mem = memory(pid)
            except OSError:
                continue
            u = self.usage[name]
            u.samples.append(mem)
            if mem.rss > u.peak.rss:
                u.peak = mem

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
