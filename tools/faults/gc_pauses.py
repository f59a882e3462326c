"""The fault harness's own garbage-collection pauses: a collection holds the GIL, so the
simulated hardware's threads (radar frames, actuator) stall for as long as it takes."""

import gc
import time
from typing import Any


class GcPauses:
    """Between `start` and `stop`: every collection of this process, and the longest
    one (ms)."""

    def __init__(self) -> None:
        self.collections = 0
        self.max_ms = 0.0
        self._t0 = 0.0

    def _callback(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            self._t0 = time.perf_counter()
            return
        self.collections += 1
        self.max_ms = max(self.max_ms, (time.perf_counter() - self._t0) * 1e3)

    def start(self) -> "GcPauses":
        gc.callbacks.append(self._callback)
        return self

    def stop(self) -> None:
        if self._callback in gc.callbacks:
            gc.callbacks.remove(self._callback)
