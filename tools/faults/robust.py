"""Faults of bad input that must end in a named refusal, never a crash or a silent stall:

- a service started on a configuration with a NUL byte in one of its strings (a path, a
  key expression, a name): exit 2 (`aeb up` and systemd do not restart it), the field
  named, no traceback; the running stack undisturbed;
- the radar service replaying a candump log with a bad stamp in the middle (`(inf)`,
  `(nan)`, a frame 1e6 s ahead): the frame counted in its status and logged, the cycles
  after it published without a gap.

Both start a process of their own beside the running stack; the replay runs under a
vehicle name of its own, so that its tracks never reach the stack's fusion.
"""

import itertools
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.clock import mono_ns
from aeb_radar_camera.common.config import ZenohMode, ZenohSettings
from aeb_radar_camera.common.keys import RADAR_STATUS, RADAR_TRACKS
from aeb_radar_camera.common.messages import BrakeState, RadarStatus, RadarTracks
from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.tools.faults.catalogue import MS, SERVICES, Context, Fault, Outcome

# python starting, loading its config and refusing it, on a loaded machine
CONFIG_EXIT_BOUND_MS = 15_000.0
# a string value in TOML text: "..." (a basic string, where \u0000 is a NUL byte)
_BASIC_STRING = re.compile(r'"(?:[^"\\\n]|\\.)*"')


def run_dir(ctx: Context) -> Path:
    """The folder holding the running stack's configs (tools/sim/session.py), absolute:
    the services started on its files run in it."""
    return (ctx.loop.log_path.parent / "run").resolve()


class BadConfigStrings(Fault):
    """One service started (beside the running one) on its own running config with a NUL
    byte put into one of its strings, picked at random."""

    name = "bad config strings"
    required = "exit 2, the field named, no traceback; the stack stays armed"

    def available(self, ctx: Context) -> str:
        return "" if run_dir(ctx).is_dir() else f"no {run_dir(ctx)}"

    def inject(self, ctx: Context) -> Outcome:
        service = ctx.rng.choice(SERVICES)
        source = run_dir(ctx) / f"{service}.toml"
        lines = source.read_text().splitlines(keepends=True)
        spots = [(i, m.start() + 1 + ctx.rng.randrange(m.end() - m.start() - 1))
                 for i, line in enumerate(lines) if not line.lstrip().startswith("#")
                 for m in _BASIC_STRING.finditer(line.split(" #")[0])]
        if not spots:
            return Outcome(False, None, f"{source.name} has no string to spoil")
        i, at = ctx.rng.choice(spots)
        lines[i] = lines[i][:at] + "\\u0000" + lines[i][at:]
        bad = source.with_name(f"{service}-nul.toml")
        bad.write_text("".join(lines))
        mark = ctx.observer.status.mark()
        t0 = mono_ns()
        try:
            run = subprocess.run([sys.executable, "-m", f"aeb_radar_camera.services.{service}",
                                  "-c", str(bad)],
                                 capture_output=True, text=True, timeout=60,
                                 cwd=source.parent)
        except subprocess.TimeoutExpired:
            return Outcome(False, None, f"{service} still running 60 s after start on a "
                                        f"NUL byte in {lines[i].strip()[:60]!r}")
        finally:
            bad.unlink(missing_ok=True)
        exit_ms = (mono_ns() - t0) / MS
        line = lines[i].strip().replace("\\u0000", "<NUL>")[:60]
        detail = f"{service}: {line}: rc {run.returncode}"
        # refused by the loader's NUL check or by the field's own validation before it
        # (a name's pattern, an enum): either way a ConfigError naming the field
        if run.returncode != 2 or "Traceback" in run.stderr \
                or "invalid configuration" not in run.stderr:
            last = run.stderr.strip().splitlines()[-1:] or [""]
            return Outcome(False, exit_ms, f"{detail}; {last[0][:120]}")
        failsafe = [s for s in ctx.observer.status.since(mark)
                    if s.msg.state is BrakeState.FAILSAFE]
        if failsafe:
            return Outcome(False, exit_ms, f"{detail}; the brake went FAILSAFE", lost=1)
        return Outcome(exit_ms <= CONFIG_EXIT_BOUND_MS, exit_ms, detail,
                       bound_ms=CONFIG_EXIT_BOUND_MS)


RECORDING = DEPLOY / "recordings" / "ars408" / "candump-2026-06-24_154259.log"
REPLAY_VEHICLE = "faults-replay"     # keys of its own: the stack's fusion never sees them
REPLAY_S = 3.0                       # recorded seconds played, the bad frame in the middle
# The widest gap between two published cycles allowed around the bad frame: a cycle is
# 75 ms; a stall is unbounded
REPLAY_GAP_BOUND_MS = 500.0
BAD_STAMPS = {"inf": "bus:replay_bad_stamp", "nan": "bus:replay_bad_stamp",
              "ahead": "bus:replay_stamp_jump"}


def bad_stamp_log(path: Path, kind: str, seconds: float = REPLAY_S) -> Path:
    """The recording's first `seconds` with one more frame in the middle, stamped
    `(inf)`, `(nan)` or 1e6 s after its neighbours (`kind`)."""
    lines = RECORDING.read_text().splitlines(keepends=True)
    t0 = float(lines[0].split(")")[0][1:])
    kept = [ln for ln in lines if float(ln.split(")")[0][1:]) - t0 < seconds]
    stamp = {"inf": "inf", "nan": "nan"}.get(kind, f"{t0 + seconds / 2 + 1e6:.6f}")
    middle = len(kept) // 2
    frame = kept[middle][kept[middle].index(")"):]
    path.write_text("".join(kept[:middle]) + f"({stamp}" + frame + "".join(kept[middle:]))
    return path


class BadReplayStamps(Fault):
    """A radar service replaying (paced, real time) a log with one bad stamp."""

    name = "bad replay stamps"
    required = "counted and logged; the cycles after it published without a gap"

    def available(self, ctx: Context) -> str:
        return "" if RECORDING.is_file() else f"no {RECORDING}"

    def inject(self, ctx: Context) -> Outcome:
        kind = ctx.rng.choice(sorted(BAD_STAMPS))
        counter = BAD_STAMPS[kind]
        folder = run_dir(ctx)
        log = bad_stamp_log(folder / "replay-bad-stamp.log", kind)
        config = folder / "radar-replay-bad-stamp.toml"
        config.write_text(f"""vehicle = "{REPLAY_VEHICLE}"
[zenoh]
connect = ["{ctx.loop.endpoint}"]
[radar]
status_period_s = 0.25
[radar.can]
interface = "replay"
[radar.replay]
file = "{log}"
pace = "realtime"
loop = false
exit_at_end = true
[[radar.sensors]]
name = "front"
sensor_id = 0
""")
        cycles: list[int] = []
        statuses: list[RadarStatus] = []
        lock = threading.Lock()

        def on_tracks(msg: RadarTracks, key: str) -> None:
            with lock:
                cycles.append(mono_ns())

        def on_status(msg: RadarStatus, key: str) -> None:
            with lock:
                statuses.append(msg)

        settings = ZenohSettings(mode=ZenohMode.CLIENT, connect=(ctx.loop.endpoint,))
        with Bus.open(settings, REPLAY_VEHICLE, "faults") as bus:
            bus.subscribe(RADAR_TRACKS, on_tracks, sensor="front")
            bus.subscribe(RADAR_STATUS, on_status, sensor="front")
            proc = subprocess.Popen([sys.executable, "-m", "aeb_radar_camera.services.radar", "-c",
                                     str(config)],
                                    stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                    text=True, cwd=folder)
            try:
                out, _ = proc.communicate(timeout=REPLAY_S + 60)
            except subprocess.TimeoutExpired:
                proc.kill()
                out, _ = proc.communicate()
                return Outcome(False, None, f"{kind}: the replay never ended (stalled)")
            time.sleep(0.3)        # the last status in flight when the process ended
        with lock:
            gaps = [(b - a) / MS for a, b in itertools.pairwise(cycles)]
            counted = max((s.rejected.get(counter, 0) for s in statuses), default=0)
        detail = (f"{kind}: {len(cycles)} cycles, widest gap {max(gaps, default=0):.0f} ms, "
                  f"{counter} {counted}, rc {proc.returncode}")
        logged = f"replay_{counter.split('replay_')[1]}" in out
        if proc.returncode != 0 or not counted or not logged or len(cycles) < 20:
            return Outcome(False, max(gaps, default=None), detail
                           + ("" if logged else "; not logged"))
        widest = max(gaps)
        return Outcome(widest <= REPLAY_GAP_BOUND_MS, widest, detail,
                       bound_ms=REPLAY_GAP_BOUND_MS)
