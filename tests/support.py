"""Helpers for multi-process tests: free ports, a router process, service processes with
captured logs, and polling with deadlines (never fixed sleeps as synchronisation)."""

import fcntl
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.net import free_port, port_open
from aeb_radar_camera.tools.arrivals import Arrivals

REPO = Path(__file__).resolve().parent.parent
T = TypeVar("T")

# Deadlines are generous: CI is a loaded 2-core machine.
START_TIMEOUT_S = 60.0


def wait_for(
    predicate: Callable[[], T], timeout_s: float, interval_s: float = 0.01, what: str = ""
) -> T:
    """Poll until `predicate()` is truthy; return its value. Raises TimeoutError."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise TimeoutError(f"timed out after {timeout_s} s waiting for {what or predicate}")
        time.sleep(interval_s)


@contextmanager
def host_exclusive(name: str, timeout_s: float = 600.0) -> Iterator[None]:
    """A lock shared by every copy of the suite on this host (a file in the temporary
    directory), for the few tests that load the machine on purpose: two 10,000/s floods
    through the real-time chain at once take both cores of a 2-core host, and a pty's
    bytes then wait for the kernel's tty worker (normal scheduling) for hundreds of
    milliseconds. The rest of another copy's load runs beside it. Raises TimeoutError."""
    path = Path(tempfile.gettempdir()) / f"aeb-tests-{name}.lock"
    with open(path, "a", encoding="utf-8") as f:

        def taken() -> bool:
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                return False
            return True

        wait_for(taken, timeout_s, 0.05, f"the host-wide lock {path}")
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


class ServiceProcess:
    """A child process with stdout+stderr captured to a file, stopped on exit."""

    def __init__(self, name: str, argv: list[str], log_dir: Path,
                 env: dict[str, str] | None = None) -> None:
        self.name = name
        self.argv = argv
        self.log_path = log_dir / f"{name}.log"
        self._log = open(self.log_path, "wb")  # noqa: SIM115 (closed in stop())
        full_env = {**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})}
        self.proc = subprocess.Popen(
            argv, stdout=self._log, stderr=subprocess.STDOUT, cwd=REPO, env=full_env,
            start_new_session=True,
        )

    @property
    def pid(self) -> int:
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc.poll() is None

    def output(self) -> str:
        """What the process wrote so far (all of it once stopped)."""
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")

    def signal(self, sig: int) -> None:
        if self.alive():
            os.kill(self.proc.pid, sig)

    def stop(self, timeout_s: float = 10.0) -> int | None:
        if self.alive():
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(5)
        self._log.close()
        return self.proc.returncode


def python_module(module: str, *args: str) -> list[str]:
    return [sys.executable, "-m", module, *args]


_ROUTER_PIDS: dict[str, int] = {}


def router_pid(endpoint: str) -> int:
    """The process id of the running `router_process` at `endpoint`. Raises KeyError."""
    return _ROUTER_PIDS[endpoint]


@contextmanager
def router_process(log_dir: Path, port: int | None = None,
                   realtime_priority: int = 0) -> Iterator[str]:
    """A Zenoh router on 127.0.0.1 (its I/O threads at SCHED_FIFO `realtime_priority`
    when > 0, as deployed); yields its endpoint once it accepts connections."""
    port = port or free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    proc = ServiceProcess(f"router-{port}", python_module(
        "aeb_radar_camera.common.router", "--listen", endpoint, "--realtime-priority",
        str(realtime_priority)),
        log_dir)
    try:
        wait_for(lambda: port_open(port) or not proc.alive(), START_TIMEOUT_S, 0.05,
                 "router port")
        if not proc.alive():
            raise RuntimeError(f"router exited:\n{proc.output()}")
        _ROUTER_PIDS[endpoint] = proc.pid
        yield endpoint
    finally:
        _ROUTER_PIDS.pop(endpoint, None)
        proc.stop()


def client_settings(endpoint: str) -> ZenohSettings:
    return ZenohSettings(mode=ZenohMode.CLIENT, connect=(endpoint,))


def open_bus(endpoint: str, vehicle: str = "ego", source: str = "test") -> Bus:
    return Bus.open(client_settings(endpoint), vehicle, source)


class Collector:
    """Collects decoded messages from a subscription, each with its key; thread-safe
    waiting."""

    def __init__(self) -> None:
        self._arrivals: Arrivals[tuple[Any, str]] = Arrivals()

    def __call__(self, msg: Any, key: str) -> None:
        self._arrivals.add((msg, key))

    @property
    def items(self) -> list[tuple[Any, str]]:
        return self._arrivals.items

    @property
    def messages(self) -> list[Any]:
        return [m for m, _ in self._arrivals.items]

    def wait_count(self, n: int, timeout_s: float) -> list[Any]:
        """Every message, once there are at least `n`. Raises TimeoutError."""
        if n > 0:
            self._arrivals.wait(lambda _: True, timeout_s, n - 1, f"message #{n}")
        return self.messages

    def wait_until(self, predicate: Callable[[Any], bool], timeout_s: float) -> Any:
        """The first message satisfying `predicate`. Raises TimeoutError."""
        return self._arrivals.wait(lambda item: predicate(item[0]), timeout_s,
                                   what="matching message")[1][0]


class HealthWatch:
    """Liveliness tokens seen on the bus: `(service, instance) -> alive`."""

    def __init__(self, bus: Bus) -> None:
        self.state: dict[tuple[str, str], bool] = {}
        self.history: list[tuple[float, str, str, bool]] = []
        self._lock = threading.Lock()
        self._sub = bus.subscribe_health(self._on)

    def _on(self, service: str, instance: str, alive: bool) -> None:
        with self._lock:
            self.state[(service, instance)] = alive
            self.history.append((time.monotonic(), service, instance, alive))

    def is_alive(self, service: str, instance: str) -> bool:
        with self._lock:
            return self.state.get((service, instance), False)

    def wait_alive(self, service: str, instance: str, timeout_s: float = START_TIMEOUT_S) -> None:
        wait_for(lambda: self.is_alive(service, instance), timeout_s, 0.02,
                 f"health/{service}/{instance}")
