"""The faults: each injects once into the running stack, measures the required response
against its bound, and undoes what it did (the harness then waits for the stack to
settle before the next injection).

Required responses (docs/brake.md, docs/fusion.md, DESIGN.md):
- the command stream stops (fusion, radar or router killed or stopped, the link to
  fusion cut, CAN silent, a radar that stops mid-cycle): the brake enters FAILSAFE and
  says so on the actuator line within its deadline plus one timer period of the last
  command it accepted;
- the brake itself killed or stopped: the actuator's own watchdog trips within its TTL
  of the last line;
- the camera killed, stopped, frozen, corrupt, truncated or its clock stepped: fusion
  reports the camera unavailable (and keeps commanding: the brake stays armed);
- the actuator's serial port unplugged: the brake detects it (FAULT) and reconnects
  after the replug without a restart;
- an intruder publishing commands: refused and counted, the brake unmoved, the real
  fusion still in command;
- garbage on every key: nothing crashes, the stack stays armed.
"""

import itertools
import os
import random
import signal
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import msgspec
import numpy as np

from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.imaging import decode_bgr, encode_jpeg, jpeg_crc32
from aeb_radar_camera.common.keys import (
    BRAKE_STATUS,
    CAMERA_INFO,
    CAMERA_JPEG,
    EGO_MOTION,
    FUSION_BRAKE_CMD,
    FUSION_TARGETS,
    RADAR_CAN,
    RADAR_STATUS,
    RADAR_TRACKS,
    KeySpec,
)
from aeb_radar_camera.common.messages import (
    BrakeState,
    BrakeStatus,
    CompressedFrame,
    VerifierStatus,
)
from aeb_radar_camera.common.messages.codec import DecodeError, decode, encode
from aeb_radar_camera.services.brake.protocol import HostMode
from aeb_radar_camera.tools.faults.mutate import mutate_bytes, mutate_msgpack
from aeb_radar_camera.tools.faults.observe import Observer
from aeb_radar_camera.tools.faults.samples import example

MS = 1_000_000
SERVICES = ("radar", "camera", "fusion", "brake")


@dataclass
class Outcome:
    """One injection: did the required response come within its bound, how fast."""

    ok: bool
    response_ms: float | None
    detail: str = ""
    lost: int = 0          # e.g. actuator lines braking for an intruder, dead processes
    bound_ms: float | None = None


@dataclass
class Bounds:
    failsafe_ms: float        # brake deadline + one timer period (+ the line's latency)
    watchdog_ms: float        # actuator TTL + its own timer slack
    camera_ms: float          # fusion reports a stopped/corrupt/stepped camera
    frozen_ms: float          # ... a frozen one (needs several frames)
    unplug_ms: float          # the brake notices its port is gone
    replug_ms: float          # ... and is back on it
    refuse_ms: float          # an intruder's command counted as refused
    recover_s: float          # the stack armed again after an injection


@dataclass
class Context:
    """What an injection may use: the running stack and the harness's eyes and hands."""

    loop: Any                  # tools.sim.session.ClosedLoop
    observer: Observer
    bounds: Bounds
    rng: random.Random
    gate: Any                  # links.CanGate
    link: Any | None           # links.NetnsLink | links.RelayLink | None
    link_problem: str
    vehicle: str = "ego"

    def pid(self, service: str) -> int:
        return int(self.loop.pid(service))

    def publisher(self, spec: KeySpec[Any], **params: str) -> Any:
        return self.loop.bus.publisher(spec, **params)


# -- what is measured --------------------------------------------------------------------


def failsafe_response(ctx: Context, inject: Callable[[], None], settle_s: float = 5.0,
                      status_visible: bool = True) -> Outcome:
    """Inject, then time the first FAILSAFE line on the actuator from the last command
    the brake accepted (its status says which; when the bus is down with the fault, the
    last command the harness saw, on the same clock)."""
    obs = ctx.observer
    mark = obs.status.mark()
    t0 = mono_ns()
    inject()
    fs = obs.status.wait(lambda s: s.state is BrakeState.FAILSAFE, mark, settle_s) \
        if status_visible else None
    lines = _wait_failsafe_line(ctx, t0, settle_s)
    if not lines:
        return Outcome(False, None, "no FAILSAFE line on the actuator")
    if fs is not None:
        last_rx = fs.msg.last_cmd_rx_mono_ns
        source = "brake status"
    else:
        before = [c for c in obs.commands.since(0) if c.rx_ns <= lines[0]]
        if not before:
            return Outcome(False, None, "no command seen before the fault")
        last_rx = before[-1].rx_ns
        source = "harness's last command"
    response = (lines[0] - last_rx) / MS
    if fs is not None and fs.msg.state_since_mono_ns < t0:
        # the stack was not armed when the fault came: not a measurement of this fault
        early_ms = (t0 - fs.msg.state_since_mono_ns) / MS
        return Outcome(False, response, f"already FAILSAFE {early_ms:.0f} ms before the fault")
    return Outcome(response <= ctx.bounds.failsafe_ms, response,
                   f"from {source}; line {(lines[0] - t0) / MS:.0f} ms after the injection",
                   bound_ms=ctx.bounds.failsafe_ms)


def _wait_failsafe_line(ctx: Context, t0: int, timeout_s: float) -> list[int]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        lines = [r.t_ns for r in ctx.loop.actuator.commands_since(t0)
                 if r.cmd.mode is HostMode.FAILSAFE]
        if lines:
            return lines
        ctx.observer.actuator_events.wait(lambda e: False, ctx.observer.actuator_events.mark(),
                                          0.02)
    return []


def camera_unavailable_response(ctx: Context, inject: Callable[[], None], bound_ms: float,
                                timeout_s: float = 5.0,
                                because: Callable[[str], bool] = lambda reason: True
                                ) -> Outcome:
    """Inject, then time fusion's first report of the camera unavailable `because` of
    what was injected (its reason); the brake must stay armed meanwhile (fusion keeps
    commanding without a camera)."""
    obs = ctx.observer
    mark, smark = obs.targets.mark(), obs.status.mark()
    t0 = mono_ns()
    inject()
    got = obs.targets.wait(lambda t: t.verifier_status is VerifierStatus.UNAVAILABLE
                           and because(t.unavailable_reason), mark, timeout_s)
    failsafe = [s for s in obs.status.since(smark) if s.msg.state is BrakeState.FAILSAFE]
    sent = [(c.first_write_mono_ns, c.last_write_mono_ns) for c in ctx.loop.feed.cycles()]
    if got is None:
        return Outcome(False, None, "fusion never reported the camera unavailable",
                       lost=len(failsafe) > 0)
    response = (got.rx_ns - t0) / MS
    detail = got.msg.unavailable_reason[:80]
    if failsafe:
        return Outcome(False, response,
                       f"brake went FAILSAFE ({stream_gaps(obs, mark, failsafe[0].msg, sent)}); "
                       f"{detail}", lost=1)
    return Outcome(response <= bound_ms, response, detail, bound_ms=bound_ms)


def _widest_gap(stamps: list[int]) -> tuple[int, int]:
    """(width, start) of the widest step between consecutive stamps (0, 0 for fewer
    than two)."""
    return max(((b - a, a) for a, b in itertools.pairwise(sorted(stamps))), default=(0, 0))


def stream_gaps(obs: Observer, targets_mark: int, failsafe: BrakeStatus,
                sent: Sequence[tuple[int, int]] = ()) -> str:
    """Where the command stream stopped before the brake's FAILSAFE status: the widest gap
    (ms, and when it began relative to that status; one still open at the status ends
    there) in each hop - the simulated radar's cycles written to its link (`sent`: first
    and last write of each), the cycles the radar received and published, those fusion
    received and the commands it published - all on this host's monotonic clock (the
    services' own stamps, not the harness's receipt, so that a slow harness does not
    show as a gap); the longest write of a cycle; and how many commands fusion published
    after the brake's last receipt (those it never got)."""
    until_ns = failsafe.header.pub_mono_ns
    since = min((t.msg.header.pub_mono_ns for t in obs.targets.since(targets_mark)),
                default=until_ns - 2_000 * MS) - 500 * MS
    written = [(a, b) for a, b in sent if since <= a <= until_ns]
    radar = [t.msg.header.pub_mono_ns for t in obs.tracks.since(0)
             if since <= t.msg.header.pub_mono_ns <= until_ns]
    # the radar stamps a cycle with the wall time its last frame came: on this host's
    # monotonic clock by the offset between the two clocks now
    offset = wall_ns() - mono_ns()
    radar_rx = [t.msg.header.stamp_ns - offset for t in obs.tracks.since(0)
                if since <= t.msg.header.pub_mono_ns <= until_ns]
    targets = [t.msg for t in obs.targets.since(0) if since <= t.msg.header.pub_mono_ns <= until_ns]
    fusion_rx = [t.header.pub_mono_ns - t.processing_ns for t in targets]
    commands = [c.msg.header.pub_mono_ns for c in obs.commands.since(0)
                if since <= c.msg.header.pub_mono_ns <= until_ns]
    parts = []
    for name, stamps in (("simulated radar wrote", [a for a, _ in written]),
                         ("radar received", radar_rx), ("radar published", radar),
                         ("fusion received", fusion_rx), ("fusion commanded", commands)):
        width, start = _widest_gap([*stamps, until_ns])    # a gap still open counts
        parts.append(f"{name} gap {width / MS:.0f} ms at {(start - until_ns) / MS:+.0f} ms")
    longest = max((b - a for a, b in written), default=0)
    parts.append(f"longest cycle write {longest / MS:.0f} ms")
    unreceived = sum(1 for t in commands if t > failsafe.last_cmd_rx_mono_ns)
    parts.append(f"{unreceived} commands published after the brake's last receipt")
    return ", ".join(parts)


# -- the faults ------------------------------------------------------------------------------


class Fault:
    """One kind of fault. `inject` returns the outcome and has undone the fault when it
    returns (the process restarted or continued, the link back)."""

    name = ""
    required = ""

    def available(self, ctx: Context) -> str:
        """Empty when it can run here, else why not."""
        return ""

    def inject(self, ctx: Context) -> Outcome:
        raise NotImplementedError


class KillOrStop(Fault):
    def __init__(self, service: str, sig: signal.Signals) -> None:
        self.service, self.sig = service, sig
        verb = "SIGKILL" if sig is signal.SIGKILL else "SIGSTOP"
        self.name = f"{verb} {service}"
        self.required = {
            "brake": "actuator watchdog trips (TTL of the last line)",
            "camera": "fusion: camera unavailable, brake stays armed",
        }.get(service, "brake FAILSAFE (deadline + timer period of the last command)")

    def inject(self, ctx: Context) -> Outcome:
        pid = ctx.pid(self.service) if self.service != "router" else \
            _router_pid(ctx)
        try:
            if self.service == "brake":
                return self._brake(ctx, pid)
            if self.service == "camera":
                return camera_unavailable_response(
                    ctx, lambda: os.kill(pid, self.sig), ctx.bounds.camera_ms)
            return failsafe_response(ctx, lambda: os.kill(pid, self.sig),
                                     status_visible=self.service != "router")
        finally:
            if self.sig is signal.SIGSTOP:
                os.kill(pid, signal.SIGCONT)

    def _brake(self, ctx: Context, pid: int) -> Outcome:
        events = ctx.observer.actuator_events
        mark = events.mark()
        os.kill(pid, self.sig)
        trip = events.wait(lambda e: e.kind == "watchdog", mark, 5.0)
        if trip is None:
            return Outcome(False, None, "the actuator's watchdog never tripped")
        lines = [r.t_ns for r in ctx.loop.actuator.commands_since(0) if r.t_ns <= trip.rx_ns]
        if not lines:
            return Outcome(False, None, "no line before the trip")
        response = (trip.rx_ns - lines[-1]) / MS
        return Outcome(response <= ctx.bounds.watchdog_ms, response, "from the last line",
                       bound_ms=ctx.bounds.watchdog_ms)


def _router_pid(ctx: Context) -> int:
    proc = ctx.loop.supervisor.child("router").proc
    if proc is None:
        raise KeyError("router is not running")
    return int(proc.pid)


class LinkCut(Fault):
    name = "link cut fusion <-> router"
    required = "brake FAILSAFE (deadline + timer period of the last command)"

    def __init__(self, down_s: float = 0.6) -> None:
        self.down_s = down_s

    def available(self, ctx: Context) -> str:
        return ctx.link_problem if ctx.link is None else ""

    def inject(self, ctx: Context) -> Outcome:
        link = ctx.link
        assert link is not None
        try:
            out = failsafe_response(ctx, link.cut)
            out.detail = f"{link.kind}; {out.detail}"
            time.sleep(max(0.0, self.down_s - (out.response_ms or 0) / 1e3))  # the outage
            return out
        finally:
            link.restore()


class CanSilence(Fault):
    def __init__(self, mid_cycle: bool) -> None:
        self.mid_cycle = mid_cycle
        self.name = "radar stops mid-cycle" if mid_cycle else "CAN silence"
        self.required = "brake FAILSAFE (deadline + timer period of the last command)"

    def inject(self, ctx: Context) -> Outcome:
        gate, feed = ctx.gate, ctx.loop.feed
        try:
            if not self.mid_cycle:
                return failsafe_response(ctx, gate.silence)
            cycles = feed.cycles()
            n = cycles[-1].n_returns if cycles else 4
            cut_at = 1 + ctx.rng.randrange(max(1, 3 * n))   # a frame inside the cycle

            def arm_on_next_cycle() -> None:
                def once(sent: Any, frames: Any) -> None:
                    feed.on_cycle = None
                    gate.silence(cut_at)
                feed.on_cycle = once

            out = failsafe_response(ctx, arm_on_next_cycle)
            out.detail = f"cut after frame {cut_at} of a cycle; {out.detail}"
            return out
        finally:
            feed.on_cycle = None
            gate.restore()


class CameraImpostorFrames(Fault):
    """The camera paused while the harness plays it: frozen (the last real frame again
    with fresh stamps), corrupt (bit flips in the JPEG), truncated JPEGs, or frames
    whose stamps jumped (the camera host's wall clock stepped; SIMULATED in the frames'
    stamps: the machine's clock is shared and is not touched)."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.name = {"frozen": "frozen camera", "noisy": "noisy frozen camera",
                     "corrupt": "corrupt JPEGs",
                     "truncated": "truncated JPEGs",
                     "clock": "camera clock step (+-2 s)"}[kind]
        self.required = "fusion: camera unavailable, brake stays armed"

    def available(self, ctx: Context) -> str:
        return "" if ctx.observer.frame_payload else "no camera frame seen yet"

    def reason_fits(self, reason: str) -> bool:
        """Fusion's reason names what was injected: an unusable frame for corrupt and
        truncated JPEGs, a frame seconds from the radar cycle for a clock step, and for
        a frozen picture anything but those and a late frame (the harness's own frames
        may come late on a loaded machine; that is not the freeze being noticed)."""
        timing = reason.startswith(("nearest frame", "no camera frame"))
        if self.kind in ("corrupt", "truncated"):
            return "unusable" in reason
        if self.kind == "clock":
            return timing and _skew_ms(reason) >= 1000.0
        if self.kind == "noisy":
            return reason == "camera frozen"
        return not timing and "unusable" not in reason

    def inject(self, ctx: Context) -> Outcome:
        payload = ctx.observer.frame_payload
        assert payload is not None
        last = decode(payload, CompressedFrame)
        pub = ctx.publisher(CAMERA_JPEG, camera=last.camera)
        pid = ctx.pid("camera")
        seq = [last.header.seq]
        step_ns = ctx.rng.choice((-2, 2)) * 1_000_000_000
        # A stepped clock on a live camera: the picture goes on changing (two pictures
        # taken in turn, each with its own CRC), so that only the stamps are wrong; the
        # same picture again would be a frozen camera, which fusion reports as such.
        live = [last.jpeg, encode_jpeg(np.clip(decode_bgr(last.jpeg).astype(np.int16) + 12,
                                               0, 255).astype(np.uint8))]
        # A frozen camera that adds fresh sensor noise to its last picture (sigma 2 grey
        # levels, each frame with its own valid CRC-32): no two frames are identical
        still = decode_bgr(last.jpeg).astype(np.float32) if self.kind == "noisy" else None
        noise = np.random.default_rng(ctx.rng.randrange(2**32))

        def frame() -> bytes:
            seq[0] += 1
            jpeg, crc32 = last.jpeg, last.crc32
            if self.kind == "corrupt":
                jpeg = _flip_entropy_bits(ctx.rng, jpeg)
            elif self.kind == "truncated":
                jpeg = jpeg[:ctx.rng.randrange(len(jpeg) // 4, len(jpeg) - 2)]
            elif self.kind == "clock":
                jpeg = live[seq[0] % 2]
                crc32 = jpeg_crc32(jpeg) if last.crc32 is not None else None
            elif still is not None:
                noisy = still + noise.normal(0.0, 2.0, still.shape).astype(np.float32)
                jpeg = encode_jpeg(np.clip(noisy, 0, 255).astype(np.uint8), 85)
                crc32 = jpeg_crc32(jpeg)
            stamp = wall_ns() + (step_ns if self.kind == "clock" else 0)
            header = msgspec.structs.replace(last.header, seq=seq[0], stamp_ns=stamp,
                                             pub_mono_ns=mono_ns())
            return encode(msgspec.structs.replace(last, header=header, jpeg=jpeg,
                                                  crc32=crc32))

        def start() -> None:
            os.kill(pid, signal.SIGSTOP)

        bound = ctx.bounds.frozen_ms if self.kind in ("frozen", "noisy") else ctx.bounds.camera_ms
        done = threading.Event()

        def play() -> None:
            period = 1 / 30
            nxt = time.monotonic()
            while not done.is_set():
                pub.put_bytes(frame())
                nxt += period
                done.wait(max(0.0, nxt - time.monotonic()))

        player = threading.Thread(target=play, name="impostor-camera", daemon=True)
        try:
            def inject() -> None:
                start()
                player.start()
            return camera_unavailable_response(ctx, inject, bound,
                                               timeout_s=max(5.0, bound / 1e3 + 2),
                                               because=self.reason_fits)
        finally:
            done.set()
            if player.is_alive():
                player.join(2.0)
            os.kill(pid, signal.SIGCONT)


def _skew_ms(reason: str) -> float:
    """The |skew| in "nearest frame -2012 ms from the radar cycle ...", else 0."""
    parts = reason.split()
    try:
        return abs(float(parts[2])) if len(parts) > 3 and parts[3] == "ms" else 0.0
    except ValueError:
        return 0.0


def _flip_entropy_bits(rng: random.Random, jpeg: bytes) -> bytes:
    b = bytearray(jpeg)
    start = jpeg.find(b"\xff\xda") + 20
    for _ in range(rng.randint(1, 3)):
        i = rng.randrange(start, len(b) - 2)
        b[i] ^= 1 << rng.randrange(8)
    return bytes(b)


class SerialUnplug(Fault):
    name = "serial unplug + replug"
    required = "brake FAULT (port lost), reconnected without a restart"

    def __init__(self, unplugged_s: float = 0.3) -> None:
        self.unplugged_s = unplugged_s

    def inject(self, ctx: Context) -> Outcome:
        obs, act = ctx.observer, ctx.loop.actuator
        mark = obs.status.mark()
        before = obs.status.last()
        connects = before.msg.counters.get("serial_connects", 0) if before else 0
        t0 = mono_ns()
        act.disconnect()
        lost = obs.status.wait(lambda s: not s.actuator_connected, mark, 5.0)
        time.sleep(self.unplugged_s)          # the cable stays out this long
        t1 = mono_ns()
        act.reconnect()
        back = obs.status.wait(lambda s: s.actuator_connected and s.counters.get(
            "serial_connects", 0) > connects, mark, ctx.bounds.replug_ms / 1e3 + 5)
        if lost is None:
            return Outcome(False, None, "the brake never reported the port lost")
        detect = (lost.msg.state_since_mono_ns - t0) / MS \
            if lost.msg.state is BrakeState.FAULT else (lost.rx_ns - t0) / MS
        if back is None:
            return Outcome(False, detect, "not reconnected", lost=1)
        replug = (back.rx_ns - t1) / MS
        ok = detect <= ctx.bounds.unplug_ms and replug <= ctx.bounds.replug_ms
        return Outcome(ok, detect, f"reconnected {replug:.0f} ms after the replug",
                       bound_ms=ctx.bounds.unplug_ms)


class Intruder(Fault):
    """The SIMULATED attacker of tools/faults/intruder.py on the harness's session."""

    name = "intruder publishes commands"
    required = "refused and counted, brake unmoved, fusion still in command"
    ATTACKS = ("ahead", "jump", "forged", "replay", "flood")

    def __init__(self, flood_s: float = 0.2) -> None:
        self.flood_s = flood_s

    def inject(self, ctx: Context) -> Outcome:
        from aeb_radar_camera.tools.faults.intruder import run as attack
        obs = ctx.observer
        last = obs.status.last()
        rejected0 = sum(last.msg.rejected.values()) if last else 0
        mark = obs.status.mark()
        started: list[int] = []     # the first attack's time (after its recording)
        sent = attack(ctx.loop.bus, "primary", self.ATTACKS, record_s=0.2,
                      replay_delay_s=0.15, flood_s=self.flood_s, flood_hz=500.0,
                      progress=lambda what: started.append(mono_ns()))
        t0 = started[0] if started else mono_ns()
        counted = obs.status.wait(lambda s: sum(s.rejected.values()) > rejected0, mark, 2.0)
        t_end = mono_ns()
        # fusion's own commands must be what the brake follows once the attack is over
        followed = obs.status.wait(lambda s: s.last_cmd_seq in _fusion_seqs(obs, t_end),
                                   obs.status.mark(), 1.0)
        braked = [r for r in ctx.loop.actuator.commands_since(t0) if r.cmd.level_pct > 0]
        response = None if counted is None else (counted.rx_ns - t0) / MS
        ok = counted is not None and not braked and followed is not None \
            and response is not None and response <= ctx.bounds.refuse_ms
        why = []
        if braked:
            why.append(f"brake moved: {len(braked)} lines up to "
                       f"{max(r.cmd.level_pct for r in braked)} %")
        if counted is None:
            why.append("no rejection counted")
        if followed is None:
            why.append("fusion not in command")
        total = sum(sent.values())
        return Outcome(ok, response, "; ".join(why) or f"{total} commands refused",
                       lost=len(braked), bound_ms=ctx.bounds.refuse_ms)


def _fusion_seqs(obs: Observer, since_ns: int) -> set[int]:
    return {c.msg.header.seq for c in obs.commands.since(max(0, obs.commands.mark() - 50))
            if c.rx_ns >= since_ns}


FLOOD_KEYS: tuple[tuple[KeySpec[Any], dict[str, str]], ...] = (
    (RADAR_TRACKS, {"sensor": "front"}), (RADAR_STATUS, {"sensor": "front"}),
    (CAMERA_JPEG, {"camera": "front"}), (CAMERA_INFO, {"camera": "front"}),
    (FUSION_TARGETS, {"instance": "primary"}), (FUSION_BRAKE_CMD, {"instance": "primary"}),
    (BRAKE_STATUS, {}), (EGO_MOTION, {}), (RADAR_CAN, {"bus": "can0"}),
)


class GarbageFlood(Fault):
    name = "garbage flood, every key"
    required = "nothing crashes, the stack stays armed"

    def __init__(self, per_key: int = 40) -> None:
        self.per_key = per_key

    def inject(self, ctx: Context) -> Outcome:
        pids = {s: ctx.pid(s) for s in SERVICES}
        pubs = [(spec, ctx.publisher(spec, **params)) for spec, params in FLOOD_KEYS]
        seeds = {spec.name: encode(example(spec.msg_type)) for spec, _ in FLOOD_KEYS
                 if spec.msg_type is not None}
        t0 = mono_ns()
        sent = 0
        for _ in range(self.per_key):
            for spec, pub in pubs:
                payload = _garbage(ctx.rng, seeds[spec.name], spec)
                pub.put_bytes(payload)
                sent += 1
            time.sleep(0.002)
        t_end = mono_ns()
        # healthy again: armed on fusion's own commands after the flood
        mark = ctx.observer.status.mark()
        ok_status = ctx.observer.status.wait(
            lambda s: s.state is BrakeState.ARMED, mark, ctx.bounds.recover_s)
        dead = [s for s, pid in pids.items() if not _alive(ctx, s, pid)]
        braked = [r for r in ctx.loop.actuator.commands_since(t0) if r.cmd.level_pct > 0]
        detail = f"{sent} payloads in {(t_end - t0) / 1e9:.1f} s"
        if braked:
            detail += f"; brake moved ({len(braked)} lines)"
        if dead:
            return Outcome(False, None, f"{', '.join(dead)} died; {detail}", lost=len(dead))
        if ok_status is None:
            return Outcome(False, None, f"brake not armed after the flood; {detail}")
        return Outcome(True, (ok_status.rx_ns - t_end) / MS, detail,
                       bound_ms=ctx.bounds.recover_s * 1000)


def _alive(ctx: Context, service: str, pid: int) -> bool:
    try:
        return ctx.pid(service) == pid
    except KeyError:
        return False


def _garbage(rng: random.Random, seed: bytes, spec: KeySpec[Any]) -> bytes:
    """A mutated payload; on the keys the harness itself reads for its verdicts
    (brake/status, fusion's targets) only ones that do not decode, so that a forged
    status cannot fool the harness (the services' handling of those keys is fuzzed
    by `aeb faults fuzz`)."""
    for _ in range(20):
        payload = mutate_msgpack(rng, seed) if rng.random() < 0.7 else mutate_bytes(rng, seed)
        if spec not in (BRAKE_STATUS, FUSION_TARGETS) or spec.msg_type is None:
            return payload
        try:
            decode(payload, spec.msg_type)
        except DecodeError:
            return payload
    return b"\x00garbage"


def catalogue() -> list[Fault]:
    """Every fault, in the order a round injects them."""
    faults: list[Fault] = []
    for svc in (*SERVICES, "router"):
        faults.append(KillOrStop(svc, signal.SIGSTOP))
    for svc in (*SERVICES, "router"):
        faults.append(KillOrStop(svc, signal.SIGKILL))
    faults += [LinkCut(), SerialUnplug(), CanSilence(False), CanSilence(True),
               CameraImpostorFrames("frozen"), CameraImpostorFrames("corrupt"),
               CameraImpostorFrames("truncated"), CameraImpostorFrames("clock"),
               Intruder(), GarbageFlood()]
    return faults
