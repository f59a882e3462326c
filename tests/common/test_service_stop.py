"""A signalled service exits: cleanly when its stop path finishes, and anyway (128 +
signal) when the stop path hangs past the grace period."""

import signal
import subprocess
import sys
import time

from tests.support import wait_for

HANGS = """
import sys, time
from aeb_radar_camera.common.service import stop_event_on_signals
stop = stop_event_on_signals(grace_s=float(sys.argv[1]))
print("ready", flush=True)
stop.wait()
time.sleep(600)      # a stop path that never finishes
"""

CLEAN = """
from aeb_radar_camera.common.service import stop_event_on_signals
stop = stop_event_on_signals(grace_s=600.0)
print("ready", flush=True)
stop.wait()
print("stopped cleanly", flush=True)
"""


def _start(code: str, *args: str) -> subprocess.Popen[str]:
    proc = subprocess.Popen([sys.executable, "-c", code, *args], stdout=subprocess.PIPE,
                            text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    return proc


def test_a_hanging_stop_path_exits_after_the_grace_period():
    proc = _start(HANGS, "0.5")
    try:
        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        code = wait_for(lambda: proc.poll(), 30, 0.02, "exit after the grace period")
        elapsed = time.monotonic() - t0
        assert code == 128 + signal.SIGTERM
        assert elapsed >= 0.5
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_a_clean_stop_is_not_cut_short_and_the_watchdog_does_not_hold_the_exit():
    proc = _start(CLEAN)
    try:
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=30)
        assert proc.returncode == 0 and "stopped cleanly" in out
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


HOLDS_GIL = """
import ctypes, sys
from aeb_radar_camera.common.service import stop_event_on_signals
stop = stop_event_on_signals(grace_s=float(sys.argv[1]))
print("ready", flush=True)
stop.wait()
ctypes.PyDLL(None).sleep(600)   # a stop path hanging in native code, the GIL held
"""

OTHER_THREAD = """
import os, signal, threading
from aeb_radar_camera.common.service import stop_event_on_signals
stop = stop_event_on_signals(grace_s=600.0)
parked = threading.Event()
worker = threading.Thread(target=parked.wait, daemon=True)
worker.start()
print("ready", flush=True)
input()
# The signal as the kernel may deliver it: to a thread other than the main one.
signal.pthread_kill(worker.ident, signal.SIGTERM)
stop.wait()
print("stopped cleanly", flush=True)
"""


def test_a_stop_path_holding_the_gil_is_ended_by_the_kernel():
    """The watchdog's thread cannot run while native code holds the GIL: the kernel's
    timer (SIGALRM, default action) ends the process a second after the grace period."""
    proc = _start(HOLDS_GIL, "0.5")
    try:
        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        code = wait_for(lambda: proc.poll(), 30, 0.02, "exit after the grace period")
        assert code == -signal.SIGALRM and time.monotonic() - t0 >= 1.5
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_a_signal_delivered_to_another_thread_still_stops_the_main_thread():
    proc = subprocess.Popen([sys.executable, "-c", OTHER_THREAD], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        out, _ = proc.communicate("go\n", timeout=30)
        assert proc.returncode == 0 and "stopped cleanly" in out
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
