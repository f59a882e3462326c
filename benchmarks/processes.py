"""Stopping the helper processes a benchmark started (routers, relays, a null service)."""

import subprocess
from collections.abc import Iterable
from typing import Any


def stop_processes(procs: Iterable[subprocess.Popen[Any] | None], timeout_s: float = 10.0
                   ) -> None:
    """SIGTERM to every process still running (all first, so that they stop in parallel),
    then wait for each; SIGKILL whichever is still running `timeout_s` later. `None`
    entries (a process that was never started) are skipped."""
    running = [p for p in procs if p is not None and p.poll() is None]
    for p in running:
        p.terminate()
    for p in running:
        try:
            p.wait(timeout_s)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
