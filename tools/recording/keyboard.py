"""The replay's keys on a terminal, as `ros2 bag play` has them: space pauses and resumes,
s (or the right arrow) sends the next message alone, the up and down arrows (or + and -)
make it 10% faster or slower, h shows them.

Only when stdin is a terminal this process may read (not in a pipe, not in the
background); the terminal is put in cbreak mode (keys arrive one by one, no echo, Ctrl-C
still a signal) and restored on exit, however the replay ends.
"""

import contextlib
import os
import select
import sys
import termios
import threading
import tty
from collections.abc import Callable, Iterator
from typing import IO

from aeb_radar_camera.tools.recording.playback import Playback

HELP = "keys: space pause/resume, s or right arrow: one message, up/down or +/-: rate, h: help"
_ARROWS = {b"\x1b[A": "faster", b"\x1b[B": "slower", b"\x1b[C": "step",
           b"\x1bOA": "faster", b"\x1bOB": "slower", b"\x1bOC": "step"}
_KEYS = {b" ": "pause", b"s": "step", b"+": "faster", b"=": "faster", b"-": "slower",
         b"h": "help", b"?": "help"}


def commands(data: bytes) -> list[str]:
    """The commands in what the terminal sent (several keys may arrive at once)."""
    out, i = [], 0
    while i < len(data):
        arrow = next((seq for seq in _ARROWS if data.startswith(seq, i)), None)
        if arrow is not None:
            out.append(_ARROWS[arrow])
            i += len(arrow)
            continue
        key = data[i:i + 1]
        if key in _KEYS:
            out.append(_KEYS[key])
        i += 1
    return out


def apply(playback: Playback, command: str) -> str:
    """Carry out one command; returns what to tell the person."""
    at = f"{playback.into_pass_s:.3f} s"
    if command == "pause":
        return (f"paused at {at}, {playback.released} messages out ({HELP})"
                if playback.toggle_pause()
                else f"playing from {at} at {playback.rate:.3g}x")
    if command == "step":
        playback.step()
        return f"step: the message after {at}"
    if command in ("faster", "slower"):
        rate = playback.faster() if command == "faster" else playback.slower()
        return f"rate {rate:.3g}x" + (" (--fast: no pauses, the rate does not apply)"
                                      if playback.fast else "")
    return HELP


def interactive(stream: IO[str]) -> bool:
    """Whether `stream` is a terminal this process reads in the foreground."""
    try:
        fd = stream.fileno()
        return os.isatty(fd) and os.tcgetpgrp(fd) == os.getpgrp()
    except (OSError, ValueError):
        return False


@contextlib.contextmanager
def keyboard(playback: Playback, stop: threading.Event,
             say: Callable[[str], None]) -> Iterator[bool]:
    """Read keys from stdin for the `with` block when it is an interactive terminal
    (yields whether it is); the terminal as it was afterwards."""
    if not interactive(sys.stdin):
        yield False
        return
    fd = sys.stdin.fileno()
    saved = termios.tcgetattr(fd)
    done = threading.Event()

    def read() -> None:
        while not (stop.is_set() or done.is_set()):
            ready, _, _ = select.select([fd], [], [], 0.1)
            if not ready:
                continue
            try:
                data = os.read(fd, 64)
            except OSError:
                return
            if not data:
                return
            for command in commands(data):
                say(apply(playback, command))

    tty.setcbreak(fd)
    thread = threading.Thread(target=read, name="replay-keys", daemon=True)
    try:
        thread.start()
        say(HELP)
        yield True
    finally:
        done.set()
        thread.join(1.0)
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
