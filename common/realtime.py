"""Real-time scheduling for the threads on the radar-to-brake path, and a garbage
collector that leaves start-up objects alone.

On a loaded machine the latency of the chain is mostly waiting: a woken thread waits for
a CPU that runs something else (a camera encoding, another job). SCHED_FIFO makes the few
threads that carry a radar cycle run the moment they are woken, ahead of every normal
thread. What gets it (settings: common/config/realtime.py, `priority` > 0):

- the thread that runs a service's latency path, set by the thread itself the first time
  it runs it (`ThreadRealtime.ensure`): the radar's CAN loop, the Zenoh callback that
  carries a radar cycle in fusion and a command in the brake;
- the process's Zenoh receive and transmit threads (zenoh's `rx-N` and `tx-N` runtimes,
  found by thread name), which carry every sample in and out;
- every other thread of the process still on normal scheduling, one priority lower: a
  frame decoder or a serial reader that holds the GIL when a radar cycle arrives is then
  never preempted by the rest of the machine while the latency path waits for it
  (Python's GIL has no priority inheritance).

Each of these threads blocks (select, epoll, condition variables) between samples and
does bounded work per sample; none polls. With a priority, the GIL's switch interval is
also cut to 0.5 ms: a real-time thread waiting for the GIL held by a normal thread (a
frame decoder) gets it that much sooner. Linux caps real-time threads at 95% of each CPU
(kernel.sched_rt_runtime_us), so a bug cannot freeze the machine. Threads that a
real-time thread creates inherit its policy (pthread's default); the services create
their other threads (decoders, timers, serial readers) from the main thread before.
Refused (no root or CAP_SYS_NICE, not Linux), a warning is logged once and the thread
keeps normal scheduling.

`apply_process` also freezes the collector (gc.freeze once started): the objects of
start-up (modules, configuration, Zenoh and numpy state) leave the collector's
generations, so that a full collection, which Python runs now and then on whatever thread
allocates, does not walk them.
"""

import gc
import logging
import os
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

from aeb_radar_camera.common.config.realtime import RealtimeSettings
from aeb_radar_camera.common.log import kv

ZENOH_IO_PREFIXES = ("rx-", "tx-")
GIL_SWITCH_INTERVAL_S = 0.0005


def set_fifo(priority: int, tid: int = 0) -> None:
    """SCHED_FIFO at `priority` for thread `tid` (0: the calling thread). Raises OSError
    (EPERM without the capability) or AttributeError (not Linux)."""
    os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))


@contextmanager
def fifo_for(priority: int) -> Iterator[bool]:
    """The calling thread at SCHED_FIFO `priority` for the `with` block, then back to its
    own policy; yields whether it was granted (not without root or CAP_SYS_NICE, nor off
    Linux, nor for `priority` 0). For an instrument that stamps an action the moment it
    is done: a real-time thread it wakes cannot run in between."""
    if priority <= 0:
        yield False
        return
    try:
        policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
        set_fifo(priority)
    except (OSError, AttributeError):
        yield False
        return
    try:
        yield True
    finally:
        os.sched_setscheduler(0, policy, param)


def thread_names() -> dict[int, str]:
    """This process's threads: native id -> name (Linux /proc; empty elsewhere)."""
    out: dict[int, str] = {}
    try:
        tids = os.listdir("/proc/self/task")
    except OSError:
        return out
    for tid in tids:
        try:
            with open(f"/proc/self/task/{tid}/comm", encoding="utf-8") as f:
                out[int(tid)] = f.read().strip()
        except (OSError, ValueError):
            continue     # the thread ended meanwhile
    return out


def zenoh_io_threads(names: dict[int, str] | None = None) -> dict[int, str]:
    """The Zenoh receive and transmit threads of this process (by their names)."""
    return {tid: name for tid, name in (thread_names() if names is None else names).items()
            if name.startswith(ZENOH_IO_PREFIXES)}


def apply_process(settings: RealtimeSettings, log: logging.Logger) -> list[str]:
    """Once the service is set up (Zenoh session open, subscriptions declared, its own
    threads started): freeze the collector and, with a priority, shorten the GIL's switch
    interval and make the Zenoh I/O threads and the other threads real-time. Returns
    `name:priority` of each thread changed (empty when refused or off)."""
    gc.collect()
    gc.freeze()
    if settings.priority <= 0:
        return []
    # A real-time thread that wants the GIL from a normal one waits up to this interval
    # before Python asks the holder to let go (5 ms by default).
    sys.setswitchinterval(min(sys.getswitchinterval(), GIL_SWITCH_INTERVAL_S))
    done: list[str] = []
    names = thread_names()
    zenoh = zenoh_io_threads(names)
    if not zenoh:
        log.warning(kv("realtime_zenoh_threads_not_found", expected="rx-N,tx-N"))
    other = max(1, settings.priority - 1)
    plan = [(tid, name, settings.priority) for tid, name in sorted(zenoh.items())]
    plan += [(tid, name, other) for tid, name in sorted(names.items())
             if tid not in zenoh and _normal(tid)]
    for tid, name, priority in plan:
        try:
            set_fifo(priority, tid)
        except ProcessLookupError:
            continue              # the thread ended meanwhile
        except (OSError, AttributeError) as exc:
            log.warning(kv("realtime_refused", thread=name, priority=priority, error=exc))
            return done
        done.append(f"{name}:{priority}")
    if done:
        log.info(kv("realtime_threads", threads=",".join(done)))
    return done


def _normal(tid: int) -> bool:
    """Still on normal scheduling (a thread made real-time on purpose keeps its own)."""
    try:
        return os.sched_getscheduler(tid) == os.SCHED_OTHER
    except OSError:
        return False


class ThreadRealtime:
    """Makes each thread that calls `ensure()` real-time, once per thread; thread-safe.
    Call it at the top of a latency-path callback or loop (a set lookup when done)."""

    def __init__(self, settings: RealtimeSettings, log: logging.Logger, what: str) -> None:
        self.priority = settings.priority
        self._log = log
        self._what = what
        self._seen: set[int] = set()
        self._lock = threading.Lock()
        self.refused = False

    def ensure(self) -> None:
        if self.priority <= 0:
            return
        tid = threading.get_native_id()
        if tid in self._seen:
            return
        with self._lock:
            if tid in self._seen:
                return
            self._seen.add(tid)
            try:
                set_fifo(self.priority)
            except (OSError, AttributeError) as exc:
                if not self.refused:
                    self._log.warning(kv("realtime_refused", thread=self._what,
                                         priority=self.priority, error=exc))
                self.refused = True
                return
            self._log.info(kv("realtime_thread", thread=self._what, tid=tid,
                              priority=self.priority))
