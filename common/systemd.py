"""The systemd service notification protocol (sd_notify(3)), spoken directly: one
datagram of ``KEY=VALUE`` lines to the AF_UNIX socket named by $NOTIFY_SOCKET (a path, or
``@name`` in the abstract namespace). Under a `Type=notify` unit a service says READY=1
once it serves; with `WatchdogSec=` it sends WATCHDOG=1 from its own loop, and systemd
restarts it when those stop (a hung loop, not only a dead process).

Outside systemd (no $NOTIFY_SOCKET) every call does nothing, so the services call these
unconditionally. Nothing here raises: a notification that cannot be sent is not a reason
to stop braking.
"""

import os
import socket
import threading
import time
from collections.abc import Callable, Mapping

# The variables systemd sets for the unit's main process; a supervisor removes them from
# its children's environment, which are not the main process.
NOTIFY_ENV = ("NOTIFY_SOCKET", "WATCHDOG_USEC", "WATCHDOG_PID")


def notify(*states: str, env: Mapping[str, str] | None = None) -> bool:
    """Send `states` (``"READY=1"``, ``"STATUS=..."``, ...) in one datagram. False when
    not run by systemd or the socket refused it."""
    address = (os.environ if env is None else env).get("NOTIFY_SOCKET", "")
    if address.startswith("@"):
        address = "\0" + address[1:]
    elif not address.startswith("/"):
        return False      # unset, or a transport we do not speak (vsock)
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC) as sock:
            sock.connect(address)
            sock.sendall("\n".join(states).encode())
    except OSError:
        return False
    return True


def ready(status: str = "") -> bool:
    """READY=1 (and a STATUS line that `systemctl status` shows)."""
    return notify("READY=1", *([f"STATUS={status}"] if status else []))


def status(text: str) -> bool:
    return notify(f"STATUS={text}")


def stopping() -> bool:
    return notify("STOPPING=1")


class Watchdog:
    """WATCHDOG=1 for a unit's `WatchdogSec=`, fed by a service's own loop.

    `feed()` is cheap enough for every iteration of a busy loop: it sends at most once
    per half watchdog interval. Disabled (every call a no-op) unless systemd asked for
    pings from this very process ($WATCHDOG_USEC, and $WATCHDOG_PID when set)."""

    def __init__(self, env: Mapping[str, str] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        env = os.environ if env is None else env
        self._env = env
        self._clock = clock
        self.interval_s: float | None = None
        try:
            usec = int(env.get("WATCHDOG_USEC", "0"))
            pid = int(env.get("WATCHDOG_PID", str(os.getpid())))
        except ValueError:
            usec, pid = 0, -1
        if usec > 0 and pid == os.getpid():
            self.interval_s = usec / 1e6
        self._next = 0.0
        self._lock = threading.Lock()
        self.sent = 0

    @property
    def enabled(self) -> bool:
        return self.interval_s is not None

    @property
    def period_s(self) -> float | None:
        """How often a loop must call `feed` at least (half the interval)."""
        return None if self.interval_s is None else self.interval_s / 2

    def feed(self) -> None:
        if self.interval_s is None:
            return
        now = self._clock()
        with self._lock:
            if now < self._next:
                return
            self._next = now + self.interval_s / 4
        if notify("WATCHDOG=1", env=self._env):
            self.sent += 1

    def wait(self, event: threading.Event, timeout_s: float) -> bool:
        """`event.wait(timeout_s)`, feeding the watchdog at least every period meanwhile
        (a loop that sleeps long between its own work). Returns whether the event is set."""
        period = self.period_s
        if period is None:
            return event.wait(timeout_s)
        end = self._clock() + timeout_s
        while True:
            self.feed()
            left = end - self._clock()
            if left <= 0:
                return event.is_set()
            if event.wait(min(left, period)):
                return True
