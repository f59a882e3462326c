"""The process shell of `aeb up`: start each process of a table, prefix its output lines,
restart it by the policy in `restart`, and stop everything cleanly.

Each child runs in its own session (process group): Ctrl-C in a terminal reaches only the
launcher, which then stops the children in reverse start order (SIGTERM to the group,
SIGKILL after the grace period). On Linux each child also asks the kernel for SIGTERM
when the launcher dies (PR_SET_PDEATHSIG), so that even a SIGKILLed launcher leaves no
orphans behind.
"""

import contextlib
import ctypes
import ctypes.util
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import IO

from aeb_radar_camera.common import systemd
from aeb_radar_camera.tools.launch.restart import RestartState, describe_exit, on_exit
from aeb_radar_camera.tools.launch.table import Launch

_PR_SET_PDEATHSIG = 1
_POLL_S = 0.05


def _load_prctl() -> Callable[..., int] | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        prctl: Callable[..., int] = libc.prctl
        return prctl
    except (OSError, AttributeError):
        return None


_prctl = _load_prctl()  # resolved before any fork: the child only makes the call


def _die_with_parent() -> None:
    if _prctl is not None:
        _prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)


class LinePrinter:
    """Writes `name | line` for every line of every child, one line at a time."""

    _COLOURS = (36, 33, 35, 32, 34, 91, 96, 93)

    def __init__(self, out: IO[str], names: list[str], colour: bool | None = None) -> None:
        self._out = out
        self._lock = threading.Lock()
        self._width = max([len(n) for n in names] + [2])
        use = out.isatty() if colour is None else colour
        self._colour = {n: self._COLOURS[i % len(self._COLOURS)] for i, n in enumerate(names)}
        self._use_colour = use

    def line(self, name: str, text: str) -> None:
        prefix = f"{name:<{self._width}} |"
        if self._use_colour and name in self._colour:
            prefix = f"\x1b[{self._colour[name]}m{prefix}\x1b[0m"
        with self._lock:
            self._out.write(f"{prefix} {text}\n")
            self._out.flush()


@dataclass
class Child:
    launch: Launch
    proc: subprocess.Popen[bytes] | None = None
    started_at: float = 0.0
    restart_at: float | None = None
    finished: bool = False          # ended and not to be restarted
    last_exit: int | None = None
    state: RestartState = field(default_factory=RestartState)
    reader: threading.Thread | None = None

    @property
    def name(self) -> str:
        return self.launch.name

    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None


class Supervisor:
    """Runs a list of launches until `stop` is set or nothing is left to run."""

    def __init__(self, launches: list[Launch], printer: LinePrinter, me: str = "up",
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.children = [Child(launch) for launch in launches]
        self._printer = printer
        self._me = me
        self._clock = clock
        self._stopping = False

    def say(self, text: str) -> None:
        self._printer.line(self._me, text)

    def child(self, name: str) -> Child:
        for c in self.children:
            if c.name == name:
                return c
        raise KeyError(name)

    def _spawn(self, child: Child) -> None:
        launch = child.launch
        # systemd's notification variables are the launcher's: a child is not the unit's
        # main process
        env = {k: v for k, v in os.environ.items() if k not in systemd.NOTIFY_ENV}
        env = {**env, "PYTHONUNBUFFERED": "1", **launch.env}
        try:
            proc = subprocess.Popen(
                launch.argv, cwd=launch.cwd, env=env, stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                start_new_session=True, preexec_fn=_die_with_parent,
            )
        except OSError as exc:
            # Treated as a failed run so the backoff applies (a device may appear later).
            self.say(f"{child.name}: cannot start: {exc}")
            child.proc = None
            self._handle_exit(child, 127, 0.0)
            return
        child.proc = proc
        child.started_at = self._clock()
        child.restart_at = None
        self.say(f"{child.name}: started pid={proc.pid}")
        child.reader = threading.Thread(target=self._pump, args=(child.name, proc),
                                        name=f"log-{child.name}", daemon=True)
        child.reader.start()

    def _pump(self, name: str, proc: subprocess.Popen[bytes]) -> None:
        assert proc.stdout is not None
        for raw in proc.stdout:
            self._printer.line(name, raw.decode("utf-8", "replace").rstrip("\r\n"))
        proc.stdout.close()

    def _handle_exit(self, child: Child, returncode: int, ran_s: float) -> None:
        child.last_exit = returncode
        decision, child.state = on_exit(child.launch.restart, child.launch.backoff,
                                        child.state, returncode, ran_s, self._stopping)
        self.say(f"{child.name}: {decision.reason}")
        if decision.restart:
            child.restart_at = self._clock() + decision.delay_s
        else:
            child.finished = True

    def start(self) -> None:
        for child in self.children:
            self._spawn(child)

    def poll(self) -> bool:
        """Reap exits, start due restarts; False once nothing runs or waits to restart."""
        now = self._clock()
        for child in self.children:
            if child.proc is not None and child.proc.poll() is not None:
                code = child.proc.returncode
                child.proc = None
                if child.reader is not None:
                    child.reader.join(1.0)
                self._handle_exit(child, code, now - child.started_at)
            elif (child.proc is None and not child.finished and child.restart_at is not None
                  and now >= child.restart_at and not self._stopping):
                self._spawn(child)
        return any(not c.finished for c in self.children)

    def run(self, stop: threading.Event, watchdog: systemd.Watchdog | None = None) -> int:
        """Start everything and supervise until `stop` is set (then stop everything) or
        every process has ended for good. Under systemd: READY=1 once every process is
        started, and `watchdog` fed by this loop. Returns 0 after a requested stop or when
        every process ended with 0, else 1."""
        self.start()
        systemd.ready(f"supervising {', '.join(c.name for c in self.children)}")
        try:
            while not stop.is_set():
                if not self.poll():
                    self.say("nothing left to run")
                    break
                if watchdog is not None:
                    watchdog.feed()
                stop.wait(_POLL_S)
        finally:
            self.shutdown()
        if stop.is_set():
            return 0
        return 0 if all(c.last_exit == 0 for c in self.children) else 1

    def shutdown(self) -> None:
        """SIGTERM every running process group in reverse start order, SIGKILL what is left
        after its grace period. Idempotent."""
        self._stopping = True
        running = [c for c in reversed(self.children) if c.running()]
        for child in running:
            assert child.proc is not None
            self.say(f"{child.name}: stopping (SIGTERM)")
            _signal_group(child.proc.pid, signal.SIGTERM)
        deadline = {c.name: self._clock() + c.launch.stop_grace_s for c in running}
        for child in running:
            assert child.proc is not None
            left = max(deadline[child.name] - self._clock(), 0.0)
            try:
                child.proc.wait(left)
            except subprocess.TimeoutExpired:
                self.say(f"{child.name}: still running after "
                         f"{child.launch.stop_grace_s:.1f} s, SIGKILL")
                _signal_group(child.proc.pid, signal.SIGKILL)
                child.proc.wait()
            # The group may hold grandchildren that outlived their parent.
            _signal_group(child.proc.pid, signal.SIGKILL)
            if child.reader is not None:
                child.reader.join(1.0)
            child.last_exit = child.proc.returncode
            self.say(f"{child.name}: stopped ({describe_exit(child.proc.returncode)})")
            child.proc = None
            child.finished = True
        for child in self.children:
            child.finished = True


def _signal_group(pgid: int, sig: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pgid, sig)
