"""Radar-to-brake latency on one host: from the last CAN frame of a radar cycle to the
brake command's bytes on the actuator's serial line, per stage, beside its floor.

    python -m benchmarks.bench_latency [--quick] [--out out/bench] [--cpu-latency-us 0]

The stack runs as in `aeb demo` (tools/sim/session.py): a router, then radar, camera,
fusion and brake, each its own process. This process is the SIMULATED vehicle: the
closed-loop simulator writes real ARS408 frames on the radar's slcan pty (python-can's
`slcan` interface in the radar, as with a USB-CAN adapter), publishes the world that the
camera's plugin renders (so fusion verifies against real frames), and the simulated
actuator (tools/sim/actuator.py) reads the brake's pty and stamps each line.
Scenarios run one after the other (threats brake, others do not) with the empty road in
between, so every decision path is in the figures.

The floor, in the same run, interleaved half a radar period after each cycle: the same
frames written on a second slcan pty, read by three relay processes that do nothing but
forward (benchmarks/floor_relay.py): pty -> relay -> Zenoh hop (RadarTracks' key, QoS and
size, through the same router) -> relay -> Zenoh hop (BrakeCommand's) -> relay -> a
command line on a serial pty that this process reads. Two floors are reported:
- same transport: last frame written -> line read, through the relays;
- Zenoh only: the two hops of those chains, with no work between them.

`--cpu-latency-us N` holds a PM QoS request for the run (common/cpu_latency.py): no
CPU idle state with an exit latency above N us, for the stack and its floor alike.

The benchmark's own process stamps the lines (the simulated actuator, the floor's
reader), so it keeps its GIL free at those moments: the stack's messages are queued
inside Zenoh and decoded after the run, the floor relay's reports go to a file.

Every message carries the stamps that split the chain into the same seven stages for
both (benchmarks/latency_chain.py). The bar: p99 < 3.75 ms (5% of a 75 ms radar cycle);
the p50 is reported beside both floors, with no bar. Prints a table; writes
bench_latency.json and bench_latency.png (CDF of the stack and both floors, stage
medians) under --out.
"""

import argparse
import contextlib
import json
import os
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.clock import mono_ns
from aeb_radar_camera.common.cpu_latency import CpuLatencyRefused, cpu_latency
from aeb_radar_camera.common.keys import (
    BRAKE_STATUS,
    FUSION_BRAKE_CMD,
    FUSION_TARGETS,
    RADAR_TRACKS,
)
from aeb_radar_camera.common.messages import BrakeCommand, BrakeStatus, RadarTracks, VerifiedTargets
from aeb_radar_camera.common.realtime import GIL_SWITCH_INTERVAL_S, fifo_for, set_fifo
from aeb_radar_camera.services.radar.ars408 import RadarFrame
from aeb_radar_camera.tools.machine import machine_info
from aeb_radar_camera.tools.sim.can_links import SlcanPtyLink
from aeb_radar_camera.tools.sim.pty_pair import PtyPair
from aeb_radar_camera.tools.sim.radar_feed import CycleSent, RadarFeed
from aeb_radar_camera.tools.sim.scenario import RadarLook, find_scenario, load_scenario
from aeb_radar_camera.tools.sim.session import SETTLE_TIMEOUT_S, ClosedLoop, closed_loop
from benchmarks.bench_brake import LineTimes
from benchmarks.figures import Figure
from benchmarks.floor_relay import VEHICLE as FLOOR_VEHICLE
from benchmarks.latency_chain import (
    STAGE_TITLES,
    STAGES,
    BrakeStamp,
    Chain,
    CommandStamp,
    Summary,
    TracksStamp,
    floor_chains,
    stack_chains,
    stages_ns,
    summarize,
    zenoh_ns,
)
from benchmarks.processes import stop_processes

P99_TARGET_MS = 3.75          # 5% of a 75 ms radar cycle
# Scenarios in turn until the measuring time is spent (threats brake, the others not).
SCENARIOS = ("pedestrian_standing_20kph", "no_threat_parked_cars_30kph",
             "multi_object_25kph", "pedestrian_crossing_20kph", "stationary_car_30kph",
             "no_threat_pedestrian_walking_beside_20kph")
QUICK_MEASURE_S = 10.0
FULL_MEASURE_S = 75.0
FLOOR_OFFSET_S = 0.037        # half a radar period after the stack's cycle
RELAY_START_S = 60.0
QUEUED_PER_S = 200             # per key: radar 13.3 Hz, brake status on every acknowledgement
REALTIME_PRIORITY = 20         # as deploy/*.toml [*.realtime] (0: normal scheduling)


@dataclass
class Collected:
    """What the stack published, as stamps.

    The benchmark's own process also runs the simulated actuator, whose thread stamps
    each brake line as it arrives: a Zenoh callback decoding the stack's messages here
    would hold this process's GIL at that very moment (the targets follow the command the
    line answers) and delay the stamp. So the messages are queued inside Zenoh with no
    Python running (`Bus.subscribe_queued`) and decoded after the run (`drain`)."""

    tracks: list[TracksStamp] = field(default_factory=list)
    processing_ns: dict[int, int] = field(default_factory=dict)
    commands: dict[int, CommandStamp] = field(default_factory=dict)
    brake: dict[int, BrakeStamp] = field(default_factory=dict)
    _subs: list[tuple[Any, Any, Callable[[Any, str], None]]] = field(default_factory=list)

    def on_tracks(self, msg: RadarTracks, key: str) -> None:
        self.tracks.append(TracksStamp(msg.meas_counter, msg.header.seq,
                                       msg.last_frame_mono_ns, msg.header.pub_mono_ns))

    def on_targets(self, msg: VerifiedTargets, key: str) -> None:
        self.processing_ns[msg.radar_seq] = msg.processing_ns

    def on_command(self, msg: BrakeCommand, key: str) -> None:
        self.commands[msg.radar_seq] = CommandStamp(msg.header.seq, msg.header.pub_mono_ns)

    def on_status(self, msg: BrakeStatus, key: str) -> None:
        if msg.cmd_to_serial_us is None or msg.last_cmd_rx_mono_ns <= 0:
            return
        self.brake.setdefault(msg.last_cmd_seq, BrakeStamp(
            msg.last_cmd_rx_mono_ns,
            msg.last_cmd_rx_mono_ns + round(msg.cmd_to_serial_us * 1000)))

    def subscribe(self, bus: Bus, measure_s: float, instance: str = "primary") -> None:
        """Queue every message of the four keys for `measure_s` seconds of cycles (and
        generous margins: a full queue would make Zenoh wait)."""
        capacity = max(4096, round(measure_s * QUEUED_PER_S))
        for spec, handler, params in (
                (RADAR_TRACKS, self.on_tracks, {"sensor": "front"}),
                (FUSION_TARGETS, self.on_targets, {"instance": instance}),
                (FUSION_BRAKE_CMD, self.on_command, {"instance": instance}),
                (BRAKE_STATUS, self.on_status, {})):
            self._subs.append((spec, bus.subscribe_queued(spec, capacity, **params), handler))

    def drain(self, bus: Bus) -> None:
        """Stop queueing; every queued message into the stamps."""
        for spec, sub, handler in self._subs:
            for msg, key in bus.drain_queued(spec, sub):
                handler(msg, key)
            sub.undeclare()
        self._subs.clear()


class FloorFeed:
    """Writes each stack cycle's frames again on the floor's slcan pty, `offset_s` after
    the stack's last frame, at the same pace (RadarFeed.send_paced)."""

    def __init__(self, link: SlcanPtyLink, offset_s: float, write_priority: int = 0) -> None:
        self._pacer = RadarFeed(link, RadarLook())
        self._pacer.write_priority = write_priority
        self._offset_ns = round(offset_s * 1e9)
        self._pending: deque[tuple[int, int, list[RadarFrame]]] = deque(maxlen=8)
        self._cond = threading.Condition()
        self._stop = False
        self.written: dict[int, int] = {}
        self.errors = 0
        self._thread = threading.Thread(target=self._run, name="floor-feed", daemon=True)
        self._thread.start()

    def on_cycle(self, sent: CycleSent, frames: Sequence[RadarFrame]) -> None:
        """RadarFeed.on_cycle: called on the simulator's loop thread."""
        with self._cond:
            self._pending.append((sent.last_write_mono_ns, sent.meas_counter, list(frames)))
            self._cond.notify()

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._pending and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                end, counter, frames = self._pending.popleft()
                due = end + self._offset_ns
                while not self._stop and mono_ns() < due:
                    self._cond.wait((due - mono_ns()) / 1e9)
                if self._stop:
                    return
            try:
                _, last = self._pacer.send_paced(frames)
            except OSError:
                self.errors += 1
                continue
            self.written[counter] = last

    def stop(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify()
        self._thread.join(5)


@dataclass
class Floor:
    link: SlcanPtyLink
    feed: FloorFeed
    lines: LineTimes
    reports_path: Path

    def reports(self) -> list[tuple[int, ...]]:
        """The `serial` relay's stamp lines so far. They go to a file, read only now:
        a thread here reading them as they come would hold this process's GIL while the
        line reader stamps the very line they describe."""
        return read_reports(self.reports_path.read_text().splitlines())


def read_reports(lines: Iterable[str]) -> list[tuple[int, ...]]:
    """The `serial` relay's stamp lines; other lines (a partial last one) skipped."""
    out: list[tuple[int, ...]] = []
    for raw in lines:
        parts = raw.split()
        if len(parts) == 7:
            with contextlib.suppress(ValueError):
                out.append(tuple(int(p) for p in parts))
    return out


@contextmanager
def floor_chain(loop: ClosedLoop, work: Path, realtime_priority: int = 0) -> Iterator[Floor]:
    """The three relays on the stack's router (scheduled as the stack), their ptys, the
    interleaved feed. Raises RuntimeError when a relay does not come up."""
    link = SlcanPtyLink()
    pty = PtyPair(work / "floor-serial")
    procs: list[subprocess.Popen[str]] = []
    log = open(work / "floor-relays.log", "w")  # noqa: SIM115 (closed below)
    reports_path = work / "floor-reports.txt"
    reports_out = open(reports_path, "w")  # noqa: SIM115 (closed below)
    feed: FloorFeed | None = None
    lines: LineTimes | None = None
    up: dict[str, threading.Event] = {r: threading.Event() for r in ("can", "hop", "serial")}

    def on_health(service: str, instance: str, alive: bool) -> None:
        role = service.removeprefix("floor-")
        if alive and role in up:
            up[role].set()

    floor_bus = Bus(loop.bus.session, FLOOR_VEHICLE, "bench")   # shares the session
    sub = floor_bus.subscribe_health(on_health)
    try:
        base = [sys.executable, "-m", "benchmarks.floor_relay"]
        common_args = ["--connect", loop.endpoint, "--vehicle", FLOOR_VEHICLE,
                       "--realtime-priority", str(realtime_priority)]
        for role, extra in (("serial", ["--port", str(pty.path)]), ("hop", []),
                            ("can", ["--channel", link.path])):
            procs.append(subprocess.Popen(
                [*base, role, *common_args, *extra],
                stdout=reports_out if role == "serial" else subprocess.DEVNULL, stderr=log,
                text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"}))
        for role, event in up.items():
            if not event.wait(RELAY_START_S):
                raise RuntimeError(f"floor relay {role!r} did not come up: "
                                   f"{(work / 'floor-relays.log').read_text()[-2000:]}")
        link.wait_open(RELAY_START_S)
        lines = LineTimes(pty.master_fd)
        _instrument_realtime(lines, realtime_priority)
        feed = FloorFeed(link, FLOOR_OFFSET_S, write_stamp_priority(realtime_priority))
        yield Floor(link, feed, lines, reports_path)
    finally:
        if feed is not None:
            feed.stop()
        if lines is not None:
            lines.stop()
        sub.undeclare()
        stop_processes(procs)
        log.close()
        reports_out.close()
        link.close()
        pty.remove()


def write_stamp_priority(realtime_priority: int) -> int:
    """The SCHED_FIFO priority at which the feeds write a burst and stamp it: above the
    chain's, so that the radar service (or the floor's relay), woken by the write on the
    writer's CPU, cannot run between the write and its stamp (which then came after its
    work, up to 0.3 ms late: a negative "CAN in"). 1 when the chain is not real-time: above
    every normal thread."""
    return realtime_priority + 10 if realtime_priority > 0 else 1


def _instrument_realtime(lines: LineTimes, priority: int) -> None:
    """The threads that stamp lines as they arrive (the simulated actuator's, the floor's
    reader) run at the stack's priority, so that a stamp is the line's arrival and not
    this process's scheduling. Refused, the figures say so in the log."""
    if priority <= 0:
        return
    tids = [t.native_id for t in threading.enumerate() if t.name == "sim-actuator"]
    tids.append(lines._thread.native_id)
    for tid in tids:
        if tid is None:
            continue
        try:
            set_fifo(priority, tid)
        except (OSError, AttributeError) as exc:
            print(f"warning: the instrument threads keep normal scheduling: {exc}",
                  file=sys.stderr)
            return


def cpu_times() -> list[int]:
    """The machine's CPU time so far (/proc/stat, all CPUs): user, nice, system, idle,
    iowait, irq, softirq, steal, in clock ticks; empty where there is no /proc/stat."""
    try:
        with open("/proc/stat", encoding="ascii") as f:
            return [int(v) for v in f.readline().split()[1:9]]
    except (OSError, ValueError):
        return []


def cpu_share(before: list[int], after: list[int]) -> dict[str, float]:
    """Busy and stolen shares of the machine's CPU time between two `cpu_times()` (%).
    Steal is time the hypervisor ran something else while this VM wanted to run: no
    scheduling policy inside the VM can win it back."""
    if len(before) < 8 or len(after) < 8:
        return {}
    d = [b - a for a, b in zip(before, after, strict=True)]
    total = sum(d) or 1
    busy = total - d[3] - d[4] - d[7]
    return {"busy_pct": round(100 * busy / total, 1), "steal_pct": round(100 * d[7] / total, 1)}


@dataclass
class Measured:
    stack: list[Chain]
    floor: list[Chain]
    cycles: int
    floor_cycles: int
    seconds: float
    verdicts: list[str]
    load_before: tuple[float, float, float]
    load_after: tuple[float, float, float]
    realtime_priority: int = 0
    cpu: dict[str, float] = field(default_factory=dict)
    cpu_latency_us: int | None = None
    stamp_priority: int = 0        # the feeds' write-and-stamp priority, 0 when refused


def measure(quick: bool, out_dir: Path, log: bool = True, seconds: float | None = None,
            realtime_priority: int = 0, cpu_latency_us: int | None = None) -> Measured:
    """Run the stack and its floor together for `seconds` of cycles (default by mode);
    every chain seen at every stage. `realtime_priority` > 0: the stack, the floor's
    relays and the line readers with SCHED_FIFO (as deployed on a vehicle).
    `cpu_latency_us`: a PM QoS request held for the run (common/cpu_latency.py);
    raises CpuLatencyRefused when it cannot be made."""
    measure_s = seconds or (QUICK_MEASURE_S if quick else FULL_MEASURE_S)
    switch_interval = sys.getswitchinterval()
    if realtime_priority > 0:
        # the line readers stamp a line once they hold the GIL: as in the services
        sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
    try:
        with contextlib.ExitStack() as stack:
            if cpu_latency_us is not None:
                stack.enter_context(cpu_latency(cpu_latency_us))
            m = _measure(measure_s, out_dir, log, realtime_priority)
        m.cpu_latency_us = cpu_latency_us
        return m
    finally:
        sys.setswitchinterval(switch_interval)


def _measure(measure_s: float, out_dir: Path, log: bool, realtime_priority: int) -> Measured:
    load_before = os.getloadavg()
    collected = Collected()
    verdicts: list[str] = []
    run_dir = out_dir / "latency-run"
    with closed_loop(run_dir, log=sys.stdout if log else None,
                     realtime_priority=realtime_priority) as loop, \
            floor_chain(loop, run_dir / "run", realtime_priority) as floor:
        collected.subscribe(loop.bus, measure_s)
        t0 = mono_ns()
        cpu0 = cpu_times()
        first_cycle = len(loop.feed.cycles())
        loop.feed.write_priority = write_stamp_priority(realtime_priority)
        with fifo_for(loop.feed.write_priority) as granted:
            stamp_priority = loop.feed.write_priority if granted else 0
        loop.feed.on_cycle = floor.feed.on_cycle
        deadline = time.monotonic() + measure_s
        i = 0
        try:
            while time.monotonic() < deadline:
                sc = load_scenario(find_scenario(SCENARIOS[i % len(SCENARIOS)]))
                i += 1
                if log:
                    print(f"  {sc.name} ...", flush=True)
                result = loop.sim.run(sc, timeout_s=max(1.0, deadline - time.monotonic()))
                verdicts.append(f"{sc.name}: {result.verdict.outcome}")
                loop.sim.wait_settled(min(SETTLE_TIMEOUT_S, 10.0))
        finally:
            loop.feed.on_cycle = None
        time.sleep(0.3)     # the last chains reach the lines
        collected.drain(loop.bus)
        cycles = loop.feed.cycles()[first_cycle:]
        written = {c.meas_counter: c.last_write_mono_ns for c in cycles}
        lines = sorted(r.t_ns for r in loop.actuator.commands_since(t0))
        stack = stack_chains(written, collected.tracks, collected.processing_ns,
                             collected.commands, collected.brake, lines)
        floor_lines = sorted(t for t in floor.lines.times if t >= t0)
        fl = floor_chains(dict(floor.feed.written), floor.reports(), floor_lines)
        seconds = (mono_ns() - t0) / 1e9
        floor_cycles = len(floor.feed.written)
        cpu = cpu_share(cpu0, cpu_times())
    return Measured(stack, fl, len(cycles), floor_cycles, seconds, verdicts, load_before,
                    os.getloadavg(), realtime_priority, cpu, stamp_priority=stamp_priority)


def _ms(s: Summary | None, attr: str) -> float:
    return float("nan") if s is None else float(getattr(s, attr))


SAME_TRANSPORT = "same-transport floor"
SAME_TRANSPORT_DETAIL = "slcan pty -> 3 relays, 2 hops -> serial pty"


def figures_from(m: Measured) -> list[Figure]:
    st, fl = stages_ns(m.stack), stages_ns(m.floor)
    total = summarize(st["total"])
    floor_total = summarize(fl["total"])
    zenoh = summarize(zenoh_ns(m.floor))
    if total is None or floor_total is None or zenoh is None:
        raise RuntimeError(f"no complete chain measured (stack {len(m.stack)}, floor "
                           f"{len(m.floor)} of {m.cycles} cycles)")
    load = (f"load {m.load_before[0]:.2f} -> {m.load_after[0]:.2f} (1 min), {_cpu(m)}; "
            f"SCHED_FIFO {m.realtime_priority or 'off'}; {_conditions(m)}; "
            f"{len(m.stack)}/{m.cycles} stack and {len(m.floor)}/{m.floor_cycles} floor "
            f"cycles paired")
    same = f"{SAME_TRANSPORT}: {SAME_TRANSPORT_DETAIL}"
    bare = "Zenoh-only floor: the same 2 hops, no work"
    figs = [
        Figure("latency", "radar-to-brake p50", total.p50_ms, "ms", baseline=same,
               baseline_value=floor_total.p50_ms, note=load),
        Figure("latency", "radar-to-brake p50 vs 2 bare hops", total.p50_ms, "ms",
               baseline=bare, baseline_value=zenoh.p50_ms),
        Figure("latency", "radar-to-brake p95", total.p95_ms, "ms", baseline=same,
               baseline_value=floor_total.p95_ms),
        Figure("latency", "radar-to-brake p99", total.p99_ms, "ms", baseline=same,
               baseline_value=floor_total.p99_ms, target=f"< {P99_TARGET_MS:g} ms",
               target_met=total.p99_ms < P99_TARGET_MS,
               extra={"max_ms": total.max_ms, "floor_max_ms": floor_total.max_ms,
                      "zenoh_floor_p99_ms": zenoh.p99_ms}),
    ]
    for name in STAGES:
        s, f = summarize(st[name]), summarize(fl[name])
        figs.append(Figure(
            "latency", f"stage p50: {STAGE_TITLES[name]}", _ms(s, "p50_ms"), "ms",
            baseline="floor's same stage", baseline_value=_ms(f, "p50_ms"),
            extra={"stack": s.as_dict() if s else None, "floor": f.as_dict() if f else None}))
    return figs


def _conditions(m: Measured) -> str:
    """The CPU idle states and how the frames were stamped, for the table and notes."""
    idle = ("CPU idle states as configured" if m.cpu_latency_us is None
            else f"CPU idle exit latency held <= {m.cpu_latency_us} us")
    if not m.stamp_priority:
        # without the priority a woken service can run before the write is stamped
        idle += "; frames stamped at normal priority (SCHED_FIFO refused: CAN in may read low)"
    return idle


def _cpu(m: Measured) -> str:
    if not m.cpu:
        return "CPU share unknown"
    return f"CPU {m.cpu['busy_pct']:g}% busy, {m.cpu['steal_pct']:g}% stolen by the host"


def table(m: Measured) -> str:
    st, fl = stages_ns(m.stack), stages_ns(m.floor)
    rows = [(STAGE_TITLES[n], summarize(st[n]), summarize(fl[n])) for n in STAGES]
    rows.append(("TOTAL: last CAN frame -> brake bytes", summarize(st["total"]),
                 summarize(fl["total"])))
    zen = summarize(zenoh_ns(m.floor))
    stack_hops = summarize([a + b for a, b in zip(st["hop_radar_fusion"],
                                                  st["hop_fusion_brake"], strict=True)])
    rows.append(("the 2 Zenoh hops only", stack_hops, zen))
    out = [f"radar-to-brake latency: {len(m.stack)} stack cycles, {len(m.floor)} floor "
           f"cycles in {m.seconds:.0f} s; load avg {m.load_before[0]:.2f} -> "
           f"{m.load_after[0]:.2f}, {_cpu(m)}; SCHED_FIFO {m.realtime_priority or 'off'}; "
           f"{_conditions(m)}; "
           "times in ms",
           f"{'stage':<38}{'stack p50':>10}{'p95':>8}{'p99':>8}{'max':>8}   "
           f"{'floor p50':>10}{'p95':>8}{'p99':>8}{'max':>8}"]
    for title, s, f in rows:
        cells = []
        for x in (s, f):
            if x is None:
                cells.append(f"{'-':>10}{'-':>8}{'-':>8}{'-':>8}")
            else:
                cells.append(f"{x.p50_ms:>10.3f}{x.p95_ms:>8.3f}{x.p99_ms:>8.3f}"
                             f"{x.max_ms:>8.2f}")
        out.append(f"{title:<38}{cells[0]}   {cells[1]}")
    total, ft = summarize(st["total"]), summarize(fl["total"])
    if total and ft and zen:
        out.append(f"p50 {total.p50_ms:.3f} ms: {total.p50_ms / ft.p50_ms:.2f}x the "
                   f"{SAME_TRANSPORT}, {total.p50_ms / zen.p50_ms:.2f}x the 2 bare hops; "
                   f"p99 {total.p99_ms:.2f} ms (target < {P99_TARGET_MS:g} ms)")
    return "\n".join(out)


def plot(m: Measured, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    st, fl = stages_ns(m.stack), stages_ns(m.floor)
    fig, (a, b) = plt.subplots(1, 2, figsize=(13, 4.8))
    series = (("stack: last CAN frame -> brake bytes", st["total"], "tab:red"),
              (SAME_TRANSPORT, fl["total"], "tab:gray"),
              ("floor: 2 bare Zenoh hops", zenoh_ns(m.floor), "tab:blue"))
    for label, values, line_colour in series:
        if values:
            v = np.sort(np.asarray(values, dtype=float) / 1e6)
            a.plot(v, np.arange(1, len(v) + 1) / len(v), label=label, color=line_colour)
    a.axvline(P99_TARGET_MS, color="k", ls="--", lw=0.8, label=f"p99 target {P99_TARGET_MS} ms")
    a.axhline(0.99, color="k", ls=":", lw=0.6)
    a.set_xscale("log")
    a.set_xlabel("latency (ms, log)")
    a.set_ylabel("fraction of cycles")
    a.set_title(f"CDF over {len(m.stack)} cycles (load {m.load_before[0]:.1f})")
    a.legend(fontsize=8, loc="lower right")
    a.grid(alpha=0.3)
    left = {"stack": 0.0, "floor": 0.0}
    for i, name in enumerate(STAGES):
        colour = plt.get_cmap("tab10")(i)
        for row, (who, data) in enumerate((("stack", st), ("floor", fl))):
            s = summarize(data[name])
            w = s.p50_ms if s else 0.0
            b.barh(row, w, left=left[who], color=colour,
                   label=STAGE_TITLES[name] if row == 0 else None)
            left[who] += w
    b.set_yticks([0, 1], ["stack", "floor"])
    b.invert_yaxis()
    b.set_xlabel("sum of stage medians (ms)")
    b.set_title("where the time goes (p50 per stage)")
    b.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_json(m: Measured, figs: list[Figure], path: Path) -> Path:
    st, fl = stages_ns(m.stack), stages_ns(m.floor)
    def summ(values: Sequence[int]) -> dict[str, float] | None:
        s = summarize(values)
        return s.as_dict() if s else None
    path.write_text(json.dumps({
        "machine": machine_info(), "seconds": round(m.seconds, 1), "cycles": m.cycles,
        "floor_cycles": m.floor_cycles, "verdicts": m.verdicts,
        "load_avg_before": m.load_before, "load_avg_after": m.load_after,
        "realtime_priority": m.realtime_priority, "cpu": m.cpu,
        "cpu_latency_us": m.cpu_latency_us, "stamp_priority": m.stamp_priority,
        "stack": {n: summ(v) for n, v in st.items()},
        "floor": {n: summ(v) for n, v in fl.items()},
        "floor_zenoh_2_hops": summ(zenoh_ns(m.floor)),
        "figures": [f.to_json() for f in figs]}, indent=1))
    return path


def run(quick: bool, out_dir: Path, seconds: float | None = None,
        realtime_priority: int = REALTIME_PRIORITY,
        cpu_latency_us: int | None = None) -> list[Figure]:
    """The suite's entry point: measure, write JSON and PNG under `out_dir`, return the
    figures. Raises RuntimeError when the stack or the floor does not come up."""
    out_dir.mkdir(parents=True, exist_ok=True)
    m = measure(quick, out_dir, seconds=seconds, realtime_priority=realtime_priority,
                cpu_latency_us=cpu_latency_us)
    figs = figures_from(m)
    print(table(m), flush=True)
    write_json(m, figs, out_dir / "bench_latency.json")
    plot(m, out_dir / "bench_latency.png")
    return figs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_latency",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help=f"{QUICK_MEASURE_S:g} s of cycles instead of {FULL_MEASURE_S:g}")
    parser.add_argument("--seconds", type=float, help="measuring time (overrides the mode)")
    parser.add_argument("--realtime-priority", type=int, default=REALTIME_PRIORITY,
                        choices=range(100), metavar="0..99",
                        help="SCHED_FIFO priority of the stack, its floor and the line "
                             f"readers (default {REALTIME_PRIORITY}, as deployed; 0: off)")
    parser.add_argument("--out", default="out/bench")
    parser.add_argument("--cpu-latency-us", type=int, metavar="US",
                        help="hold a PM QoS request for the run: no CPU idle state with a "
                             "longer exit latency (0: idle CPUs poll; root only). Default: "
                             "the machine's idle states as they are")
    args = parser.parse_args(argv)
    if args.cpu_latency_us is not None and args.cpu_latency_us < 0:
        parser.error("--cpu-latency-us must be >= 0")
    out = Path(args.out)
    t0 = time.monotonic()
    try:
        figs = run(args.quick, out, args.seconds, args.realtime_priority, args.cpu_latency_us)
    except CpuLatencyRefused as exc:
        print(f"error: --cpu-latency-us: {exc}", file=sys.stderr)
        return 2
    from benchmarks.report import print_table

    print()
    print_table(figs, sys.stdout)
    print(f"({time.monotonic() - t0:.0f} s; {out / 'bench_latency.json'}, "
          f"{out / 'bench_latency.png'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
