import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Protocol

import pytest

from tests.support import router_process


@pytest.fixture
def router(tmp_path: Path) -> Iterator[str]:
    """A Zenoh router process on a free loopback port; yields its endpoint."""
    with router_process(tmp_path) as endpoint:
        yield endpoint


class Runs(Protocol):
    def run(self, stop: threading.Event) -> int: ...


@pytest.fixture
def running() -> Iterator[Callable[[Runs], threading.Event]]:
    """Start a shell's `run(stop)` on a thread (the radar's, the vehicle gateway's);
    returns its stop event. Every one started is stopped at the end of the test and must
    stop within 10 s."""
    threads: list[tuple[threading.Thread, threading.Event]] = []

    def start(shell: Runs) -> threading.Event:
        stop = threading.Event()
        t = threading.Thread(target=shell.run, args=(stop,), daemon=True)
        t.start()
        threads.append((t, stop))
        return stop

    yield start
    for t, stop in threads:
        stop.set()
        t.join(10)
        assert not t.is_alive(), "the shell did not stop"
