"""The replay's clock under keyboard control: pause, step, rate; pure (fake clocks), then
`aeb replay` driven through a pseudo-terminal as a person types at it."""

import os
import pty
import re
import subprocess
import threading

import pytest

from aeb_radar_camera.common.keys import RADAR_TRACKS
from aeb_radar_camera.tools.recording.keyboard import apply, commands
from aeb_radar_camera.tools.recording.playback import RATE_STEP, Playback
from tests.support import REPO, START_TIMEOUT_S, Collector, open_bus, python_module, wait_for

S = 1_000_000_000


class Clock:
    def __init__(self) -> None:
        self.ns = 1000 * S

    def __call__(self) -> int:
        return self.ns


def playback(rate: float = 1.0) -> tuple[Playback, Clock]:
    clock = Clock()
    return Playback(rate, False, clock, clock), clock


def test_messages_are_due_at_their_recorded_spacing_over_the_rate():
    p, clock = playback(2.0)
    p.start(10 * S)
    assert p.due_mono(10 * S) == clock.ns
    assert p.due_mono(12 * S) == clock.ns + 1 * S
    assert p.time_map().wall(12 * S, 12 * S, 0) == clock.ns + 1 * S


def test_a_pause_keeps_the_position_and_resuming_plays_on_from_it():
    p, clock = playback()
    p.start(0)
    stop = threading.Event()
    assert p.wait_due(0, stop)
    clock.ns += 1 * S
    assert p.wait_due(1 * S, stop)            # due now
    assert p.toggle_pause()
    clock.ns += 60 * S                         # a minute paused
    assert not p.toggle_pause()
    # the next message keeps its spacing from the last one out, not from the start
    assert p.due_mono(2 * S) == clock.ns + 1 * S
    assert p.time_map().wall(2 * S, 2 * S, 0) == clock.ns + 1 * S


def test_a_step_lets_exactly_one_message_out_and_stays_paused():
    p, _ = playback()
    p.start(0)
    stop = threading.Event()
    p.toggle_pause()
    p.step()
    assert p.wait_due(5 * S, stop) and p.paused and p.position_ns == 5 * S
    stop_soon = threading.Timer(0.3, stop.set)
    stop_soon.start()
    assert not p.wait_due(6 * S, stop)       # no second message without a second step


def test_the_rate_changes_from_the_time_reached():
    p, clock = playback()
    p.start(0)
    clock.ns += 4 * S                          # 4 recorded seconds played
    assert p.faster() == pytest.approx(RATE_STEP)
    assert p.due_mono(4 * S + round(RATE_STEP * S)) == clock.ns + 1 * S
    assert p.slower() == pytest.approx(1.0)


def test_the_terminals_keys_become_commands():
    assert commands(b" s\x1b[A\x1b[B\x1b[C+-hx") == [
        "pause", "step", "faster", "slower", "step", "faster", "slower", "help"]
    p, _ = playback()
    p.start(0)
    assert apply(p, "pause").startswith("paused at 0.000 s, 0 messages out")
    assert apply(p, "faster") == "rate 1.1x"


SIM = REPO / "tests" / "data" / "recording" / "pedestrian_standing_20kph.mcap"


@pytest.mark.slow
def test_replay_on_a_terminal_pauses_steps_and_changes_rate_from_the_keyboard(router):
    master, slave = pty.openpty()
    proc = subprocess.Popen(python_module(
        "aeb_radar_camera.tools.cli", "replay", str(SIM), "--connect", router, "--keys",
        "radar_tracks",
        "--quiet"), stdin=slave, stdout=slave, stderr=slave, cwd=REPO,
        start_new_session=False, preexec_fn=_controlling(slave))
    os.close(slave)
    screen = Screen(master)
    try:
        with open_bus(router) as bus:
            got = Collector()
            bus.subscribe(RADAR_TRACKS, got, sensor="front")
            screen.wait_for("keys: space pause/resume")
            got.wait_count(3, START_TIMEOUT_S)
            os.write(master, b" ")
            screen.wait_for("messages out")
            said = re.search(r"paused at [\d.]+ s, (\d+) messages out", screen.text)
            assert said is not None
            out = int(said[1])
            assert len(got.wait_count(out, START_TIMEOUT_S)) == out
            for n in (1, 2, 3):
                os.write(master, b"s")
                screen.wait_count("step: the message after", n)
                assert len(got.wait_count(out + n, START_TIMEOUT_S)) == out + n
            os.write(master, b"\x1b[A")
            screen.wait_for("rate 1.1x")
            os.write(master, b" ")
            screen.wait_for("playing from")
            assert len(got.wait_count(83, START_TIMEOUT_S)) == 83
            assert proc.wait(START_TIMEOUT_S) == 0, screen.text
        seqs = [m.header.seq for m in got.messages]
        assert seqs == sorted(seqs) and len(set(seqs)) == 83   # none lost, none twice
        # the terminal is handed back as it was: echo on, line mode
        import termios
        attrs = termios.tcgetattr(master)
        assert attrs[3] & termios.ECHO and attrs[3] & termios.ICANON
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        screen.close()


def _controlling(slave: int):
    """The pty as the child's controlling terminal, its process group in the foreground
    (as a shell starts a program)."""
    def setup() -> None:
        import fcntl
        import termios
        os.setsid()
        fcntl.ioctl(slave, termios.TIOCSCTTY, 0)
    return setup


class Screen:
    """What the program wrote on its terminal, read on a thread."""

    def __init__(self, master: int) -> None:
        self.master = master
        self.text = ""
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        while True:
            try:
                data = os.read(self.master, 4096)
            except OSError:
                return
            if not data:
                return
            with self._lock:
                self.text += data.decode(errors="replace")

    def wait_for(self, needle: str) -> None:
        wait_for(lambda: needle in self.text, START_TIMEOUT_S, 0.02, repr(needle))

    def wait_count(self, needle: str, n: int) -> None:
        wait_for(lambda: self.count(needle) >= n, START_TIMEOUT_S, 0.02, repr(needle))

    def count(self, needle: str) -> int:
        with self._lock:
            return self.text.count(needle)

    def close(self) -> None:
        os.close(self.master)
