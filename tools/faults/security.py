"""Faults of a key holder and of a flood, each injected beside the running stack:

- `published key`: the published example key (a) on a brake started, beside the stack,
  on its running config pointed at a real actuator's port: refused at start (exit 2,
  the key named) unless opted in; (b) in the hands of an intruder on the simulator's
  stack, which accepts it (a simulated actuator): BRAKE 100 % at the real sequence
  number + 2 in the real session after every command of the real fusion. The brake sees
  a second sender (`seq_conflict`), goes back to what it followed, and follows the real
  fusion again once it is alone;
- `track flood`: well-formed radar tracks on radar/front/tracks as fast as the harness
  can publish them: fusion commands at most once per `min_cycle_interval_s`, the brake
  never loses its deadline and follows the real stream right after;
- `stuck subscriber`: a process subscribed to every key of the vehicle
  (tools/faults/stuck.py) frozen with SIGSTOP until camera-sized samples (on a camera
  key no service reads) have filled its link, then for longer than Zenoh's
  `wait_before_close` (5 s): the brake keeps getting fusion's commands within its
  deadline (no key waits for its slowest subscriber).
"""

import itertools
import signal
import subprocess
import sys
import threading
import time
from typing import Any

from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.command_auth import load_key
from aeb_radar_camera.common.keys import RADAR_TRACKS
from aeb_radar_camera.common.messages import BrakeState, Header, OutputMode, RadarTracks
from aeb_radar_camera.common.resources import EXAMPLE_KEYS
from aeb_radar_camera.tools.faults.catalogue import (
    MS,
    Context,
    Fault,
    Outcome,
    _fusion_seqs,
    _router_pid,
)
from aeb_radar_camera.tools.faults.robust import CONFIG_EXIT_BOUND_MS, run_dir
from aeb_radar_camera.tools.faults.stuck import wait_filled

# a /dev path that is not a pty: a real actuator's port (absent here)
REAL_PORT = "/dev/ttyACM-aeb-faults"
# the real fusion followed again after a second sender stops: the deadline (FAILSAFE),
# the conflict's own deadline and the arming window (200 + 200 + 300 ms) with a loaded
# machine's slack
KEYED_RECOVER_BOUND_MS = 3000.0
KEYED_S = 1.0
# the intruder's command moves the brake at most until the real fusion's next command
# shows the conflict: one radar cycle (75 ms) and the line's latency
KEYED_MOVE_BOUND_MS = 150.0
FLOOD_S = 1.0
# the real stream followed again after the flood: the deadline and the arming window
# (200 + 300 ms) when the brake went FAILSAFE, with a loaded machine's slack
FLOOD_RECOVER_BOUND_MS = 1500.0
MIN_CYCLE_S = 0.05


def _applied_ms(ctx: Context, t0: int, t1: int) -> float:
    lines = [r for r in ctx.loop.actuator.commands_since(t0) if r.t_ns <= t1]
    total = 0
    for a, b in zip(lines, [*lines[1:], None], strict=True):
        if a.cmd.level_pct > 0:
            total += (b.t_ns if b is not None else t1) - a.t_ns
    return total / MS


def _followed_after(ctx: Context, t_end: int, timeout_s: float) -> int | None:
    """When the brake, ARMED, follows a command fusion published after `t_end`."""
    obs = ctx.observer
    seen = obs.status.wait(lambda s: s.state is BrakeState.ARMED
                           and s.last_cmd_seq in _fusion_seqs(obs, t_end),
                           obs.status.mark(), timeout_s)
    return None if seen is None else seen.rx_ns


class PublishedKey(Fault):
    name = "published key"
    required = ("a real actuator's brake refuses it at start; on the simulator, a key "
                "holder ahead of the stream moves the brake at most one cycle and the "
                "real fusion is followed again")

    def available(self, ctx: Context) -> str:
        return "" if run_dir(ctx).is_dir() else f"no {run_dir(ctx)}"

    def inject(self, ctx: Context) -> Outcome:
        if ctx.rng.random() < 0.5:
            return self._start_refused(ctx)
        return self._keyed_ahead(ctx)

    def _start_refused(self, ctx: Context) -> Outcome:
        folder = run_dir(ctx)
        text = (folder / "brake.toml").read_text()
        bad = folder / "brake-real-port.toml"
        # the running config (the example key) with the port of a real actuator
        bad.write_text(_with_port(text, REAL_PORT))
        t0 = mono_ns()
        try:
            run = subprocess.run([sys.executable, "-m", "aeb_radar_camera.services.brake", "-c",
                                  str(bad)],
                                 capture_output=True, text=True, timeout=60, cwd=folder)
        except subprocess.TimeoutExpired:
            return Outcome(False, None, "the brake started on the example key and a real "
                                        "actuator's port (still running after 60 s)", lost=1)
        finally:
            bad.unlink(missing_ok=True)
        exit_ms = (mono_ns() - t0) / MS
        said = "INSECURE EXAMPLE KEY" in run.stderr and REAL_PORT in run.stderr
        detail = f"start on {REAL_PORT}: rc {run.returncode}"
        if run.returncode != 2 or not said or "Traceback" in run.stderr:
            return Outcome(False, exit_ms, f"{detail}; {run.stderr.strip()[-120:]}", lost=1)
        return Outcome(exit_ms <= CONFIG_EXIT_BOUND_MS, exit_ms, detail + ", key named",
                       bound_ms=CONFIG_EXIT_BOUND_MS)

    def _keyed_ahead(self, ctx: Context) -> Outcome:
        from aeb_radar_camera.tools.faults.intruder import run as attack
        key = load_key(EXAMPLE_KEYS / "primary.key")
        obs = ctx.observer
        last = obs.status.last()
        conflicts0 = last.msg.rejected.get("seq_conflict", 0) if last else 0
        started: list[int] = []
        sent = attack(ctx.loop.bus, "primary", ("keyed-ahead",), record_s=0.1,
                      replay_delay_s=0.0, flood_s=0.0, key=key, keyed_s=KEYED_S,
                      progress=lambda what: started.append(mono_ns()))
        t0 = started[0] if started else mono_ns()
        t_end = mono_ns()
        back = _followed_after(ctx, t_end, 10.0)
        moved_ms = _applied_ms(ctx, t0, t_end)
        now = obs.status.last()
        conflicts = (now.msg.rejected.get("seq_conflict", 0) if now else 0) - conflicts0
        detail = (f"{sent['keyed-ahead']} commands at seq + 2, brake applied {moved_ms:.0f} ms, "
                  f"seq_conflict {conflicts}")
        if back is None:
            return Outcome(False, None, detail + "; the real fusion not followed again",
                           lost=1)
        recovered_ms = (back - t_end) / MS
        ok = moved_ms <= KEYED_MOVE_BOUND_MS and conflicts > 0
        return Outcome(ok and recovered_ms <= KEYED_RECOVER_BOUND_MS, recovered_ms,
                       f"{detail}; followed again {recovered_ms:.0f} ms after",
                       lost=0 if moved_ms <= KEYED_MOVE_BOUND_MS else 1,
                       bound_ms=KEYED_RECOVER_BOUND_MS)


def _with_port(text: str, port: str) -> str:
    """A brake config's text with its serial port replaced (or added)."""
    lines = text.splitlines()
    out, in_serial, done = [], False, False
    for line in lines:
        stripped = line.strip()
        if stripped.startswith("["):
            if in_serial and not done:
                out.append(f'port = "{port}"')
                done = True
            in_serial = stripped.split("#")[0].strip() == "[brake.serial]"
        if in_serial and stripped.startswith("port"):
            out.append(f'port = "{port}"')
            done = True
            continue
        out.append(line)
    if in_serial and not done:
        out.append(f'port = "{port}"')
    elif not done and not in_serial:
        out += ["[brake.serial]", f'port = "{port}"']
    return "\n".join(out) + "\n"


def flood_tracks(seq: int) -> RadarTracks:
    """A well-formed radar cycle with nothing in it, stamped now."""
    now = mono_ns()
    return RadarTracks(header=Header(seq=seq, source="radar/front", stamp_ns=wall_ns(),
                                     pub_mono_ns=now),
                       sensor="front", mode=OutputMode.OBJECTS, meas_counter=seq,
                       complete=True, n_detections=0, n_prefiltered=0,
                       last_frame_mono_ns=now, processing_ns=1000, tracks=())


class TrackFlood(Fault):
    name = "track flood"
    required = ("fusion commands at most once per 50 ms; the brake follows the real stream "
                "within deadline + arming of the flood's end")

    def inject(self, ctx: Context) -> Outcome:
        obs = ctx.observer
        pub = ctx.publisher(RADAR_TRACKS, sensor="front")
        status_mark, cmd_mark = obs.status.mark(), obs.commands.mark()
        stop = threading.Event()
        published = [0]

        def flood() -> None:
            seq = 1 << 40       # far from the radar's own numbers
            while not stop.is_set():
                pub.put(flood_tracks(seq))
                seq += 1
                published[0] += 1

        t0 = mono_ns()
        thread = threading.Thread(target=flood, daemon=True)
        thread.start()
        time.sleep(FLOOD_S)
        stop.set()
        thread.join(5)
        t_end = mono_ns()
        pub.undeclare()
        back = _followed_after(ctx, t_end, 10.0)
        commands = [c for c in obs.commands.since(cmd_mark) if t0 <= c.rx_ns <= t_end]
        rate = len(commands) / ((t_end - t0) / 1e9)
        failsafe = [s for s in obs.status.since(status_mark)
                    if s.msg.state is BrakeState.FAILSAFE]
        detail = (f"{published[0] / FLOOD_S:.0f} tracks/s for {FLOOD_S:g} s: fusion "
                  f"{rate:.1f} commands/s")
        if back is None:
            return Outcome(False, None, detail + "; the brake not following fusion", lost=1)
        response = (back - t_end) / MS
        # a FAILSAFE during the flood is the deadline doing its job on a starved host
        # (shown, and counted as lost); what is required is fusion's bounded rate and the
        # real stream followed right after
        ok = rate <= 1 / MIN_CYCLE_S * 1.1
        gaps = [(b.msg.header.pub_mono_ns - a.msg.header.pub_mono_ns) / MS
                 for a, b in itertools.pairwise(commands)]
        if gaps:
            detail += f", widest gap {max(gaps):.0f} ms"
        if failsafe:
            first = obs.status.since(status_mark)[0].msg
            last = failsafe[-1].msg
            grew = {k: v - first.rejected.get(k, 0) for k, v in last.rejected.items()
                    if v != first.rejected.get(k, 0)} if first else {}
            detail += f"; FAILSAFE ({len(failsafe)} statuses, {failsafe[0].msg.reason}; {grew})"
        return Outcome(ok and response <= FLOOD_RECOVER_BOUND_MS, response, detail,
                       lost=1 if failsafe else 0, bound_ms=FLOOD_RECOVER_BOUND_MS)


# longer than Zenoh's wait_before_close (5 s): what a BLOCK key would stall for
STUCK_OBSERVE_S = 6.0
STUCK_FILL_TIMEOUT_S = 60.0


def end_process(proc: "subprocess.Popen[Any]", grace_s: float = 10.0) -> int:
    """SIGTERM, then SIGKILL after `grace_s`: the fault's own helper process is gone
    when this returns (a load publisher stuck in a put outlived its SIGTERM once and
    ended the whole run with a TimeoutExpired). Returns its exit code."""
    proc.terminate()
    try:
        return proc.wait(grace_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait()


class StuckSubscriber(Fault):
    name = "stuck subscriber"
    required = ("a subscriber of every key frozen: the brake gets fusion's commands within "
                "its deadline throughout, no FAILSAFE")

    def inject(self, ctx: Context) -> Outcome:
        obs = ctx.observer
        argv = [sys.executable, "-m", "aeb_radar_camera.tools.faults.stuck",
                "--connect", ctx.loop.endpoint, "--vehicle", ctx.vehicle]
        proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                text=True)
        load: subprocess.Popen[str] | None = None
        try:
            assert proc.stdout is not None
            if proc.stdout.readline().strip() != "ready":
                return Outcome(False, None, "the stuck subscriber did not start")
            mark = obs.status.mark()
            proc.send_signal(signal.SIGSTOP)
            load = subprocess.Popen([*argv, "--load"], stdout=subprocess.PIPE,
                                    stderr=subprocess.DEVNULL, text=True)
            assert load.stdout is not None
            # judged only once the load runs: before it, the stack's own traffic alone
            # would leave the frozen process's queues unchanged and look full
            if load.stdout.readline().strip() != "ready":
                return Outcome(False, None, "the load did not start")
            try:
                filled, fill_s = wait_filled(proc.pid, STUCK_FILL_TIMEOUT_S,
                                             router=_router_pid(ctx))
            except TimeoutError as exc:
                return Outcome(False, None, str(exc))
            # the load stops once the link is full: what the router sends the stuck process
            # from now on waits in the router, and the stack (without real-time priorities
            # here) is not starved of CPU by the load while it is judged
            end_process(load)
            t_full = mono_ns()
            end = obs.status.wait(
                lambda s: s.header.pub_mono_ns > t_full + int(STUCK_OBSERVE_S * 1e9), mark,
                STUCK_OBSERVE_S + 30.0)
        finally:
            if proc.poll() is None:
                proc.send_signal(signal.SIGCONT)
            for p in (load, proc):
                if p is not None:
                    end_process(p)
        if end is None:
            return Outcome(False, None, "no brake status after the subscriber's link filled",
                           lost=1)
        window = [s.msg for s in obs.status.since(mark)
                  if t_full <= s.msg.header.pub_mono_ns <= end.msg.header.pub_mono_ns]
        # the brake's receipts of fusion's commands once the link is full (its status also
        # goes out on every command): the widest gap between two
        receipts = sorted({s.last_cmd_rx_mono_ns for s in window if s.last_cmd_rx_mono_ns >= t_full}
                          | {t_full, end.msg.last_cmd_rx_mono_ns})
        widest = max(b - a for a, b in itertools.pairwise(receipts)) / MS
        # entered from the full link on (one entered while the load ran and the stack was
        # starved of CPU is not this fault's)
        failsafe = [s for s in window
                    if s.state is BrakeState.FAILSAFE and s.state_since_mono_ns >= t_full]
        detail = (f"{filled / 1e6:.1f} MB unread after {fill_s:.1f} s, then "
                  f"{STUCK_OBSERVE_S:g} s: widest gap between the brake's commands")
        if failsafe:
            detail += f"; FAILSAFE ({failsafe[0].reason})"
        return Outcome(not failsafe and widest <= ctx.bounds.failsafe_ms, widest, detail,
                       bound_ms=ctx.bounds.failsafe_ms)


SIDE_VEHICLE = "faults-brake"        # keys of its own: the stack never sees this brake
SIDE_PERIOD_S = 0.02
RESTART_BOUND_MS = 15_000.0          # python starting the brake again on a loaded machine


class BrakeRestartMidStop(Fault):
    """A brake of its own beside the stack (its own simulated actuator on a pty, its own
    key, a vehicle name of its own) braking at 100 % on a command stream the harness
    publishes: SIGKILL, then the same brake started again while the stream still says
    BRAKE. The new process asks the actuator what it holds before it commands anything:
    its lines never go below 100 %."""

    name = "brake restart mid-stop"
    required = "the restarted brake's lines never release the stop (never below the level)"

    def available(self, ctx: Context) -> str:
        return "" if run_dir(ctx).is_dir() else f"no {run_dir(ctx)}"

    def inject(self, ctx: Context) -> Outcome:
        from aeb_radar_camera.common.bus import Bus
        from aeb_radar_camera.common.command_auth import CommandSigner, new_key, write_key
        from aeb_radar_camera.common.config import ZenohMode, ZenohSettings
        from aeb_radar_camera.common.keys import BRAKE_STATUS, FUSION_BRAKE_CMD
        from aeb_radar_camera.tools.faults.intruder import forged_command
        from aeb_radar_camera.tools.sim.actuator import SimActuator

        folder = run_dir(ctx) / "side-brake"
        folder.mkdir(exist_ok=True)
        key = new_key("primary")
        key_path = folder / "primary.key"
        write_key(key_path, key, overwrite=True)
        link = folder / "actuator"
        config = folder / "brake.toml"
        config.write_text(f'vehicle = "{SIDE_VEHICLE}"\n[zenoh]\nconnect = ["{ctx.loop.endpoint}"]'
                          f'\n[brake]\ncommand_keys = ["{key_path}"]\n'
                          f'[brake.serial]\nport = "{link}"\n')
        sim, pair = SimActuator.on_pty(link, seed=ctx.rng.randrange(1 << 16))
        braking = threading.Event()
        stop = threading.Event()
        argv = [sys.executable, "-m", "aeb_radar_camera.services.brake", "-c", str(config)]
        procs: list[subprocess.Popen[bytes]] = []
        settings = ZenohSettings(mode=ZenohMode.CLIENT, connect=(ctx.loop.endpoint,))
        try:
            with sim, Bus.open(settings, SIDE_VEHICLE, "fusion/primary") as bus:
                bus.subscribe(BRAKE_STATUS, lambda s, k: braking.set()
                              if s.state is BrakeState.BRAKING else braking.clear())
                pub = bus.publisher(FUSION_BRAKE_CMD, instance="primary")
                signer = CommandSigner(key)

                def stream() -> None:
                    seq = 0
                    while not stop.wait(SIDE_PERIOD_S):
                        pub.put_bytes(signer.sign(forged_command(seq, "primary")))
                        seq += 1

                thread = threading.Thread(target=stream, daemon=True)
                thread.start()
                procs.append(subprocess.Popen(argv, cwd=folder, stdout=subprocess.DEVNULL,
                                              stderr=subprocess.DEVNULL))
                if not _wait(braking, 60.0):
                    return Outcome(False, None, "the side brake never braked")
                procs[0].kill()
                procs[0].wait(30)
                braking.clear()
                t_restart = mono_ns()
                procs.append(subprocess.Popen(argv, cwd=folder, stdout=subprocess.DEVNULL,
                                              stderr=subprocess.DEVNULL))
                again = _wait(braking, 60.0)
                stop.set()
                thread.join(5)
                lines = sim.commands_since(t_restart)
        finally:
            stop.set()
            for proc in procs:
                if proc.poll() is None:
                    end_process(proc, grace_s=15.0)
            pair.remove()
        if not lines:
            return Outcome(False, None, "no line from the restarted brake")
        first_ms = (lines[0].t_ns - t_restart) / MS
        levels = [r.cmd.level_pct for r in lines]
        detail = (f"restarted: first line {first_ms:.0f} ms after the restart at "
                  f"{levels[0]} %, lowest {min(levels)} % in {len(levels)} lines, "
                  f"{sim.queries} queries")
        released = min(levels) < 100
        return Outcome(not released and again and first_ms <= RESTART_BOUND_MS, first_ms,
                       detail + ("" if again else "; not BRAKING again"),
                       lost=int(released), bound_ms=RESTART_BOUND_MS)


def _wait(event: threading.Event, timeout_s: float) -> bool:
    return event.wait(timeout_s)
