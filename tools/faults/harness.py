"""The fault-injection run: one stack (the closed-loop session of `aeb demo`: router,
radar, camera, fusion and brake started by the launcher of `aeb up`, on the SIMULATED
radar link, camera and actuator), every fault injected in rounds, the stack recovering
between injections (a killed process is restarted by the launcher)."""

import gc
import random
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from aeb_radar_camera.common.command_auth import load_keyring
from aeb_radar_camera.common.config.brake import BrakeConfig
from aeb_radar_camera.common.config.loader import load_config
from aeb_radar_camera.common.messages import BrakeState, VerifierStatus
from aeb_radar_camera.common.net import free_port
from aeb_radar_camera.common.realtime import set_fifo, zenoh_io_threads
from aeb_radar_camera.services.brake.shell import TIMER_PERIOD_S
from aeb_radar_camera.tools.faults.catalogue import SERVICES, Bounds, Context, Fault, Outcome
from aeb_radar_camera.tools.faults.gc_pauses import GcPauses
from aeb_radar_camera.tools.faults.links import CanGate, NetnsLink, RelayLink
from aeb_radar_camera.tools.faults.observe import Observer
from aeb_radar_camera.tools.faults.registry import all_faults
from aeb_radar_camera.tools.launch.table import Launch
from aeb_radar_camera.tools.sim.session import closed_loop

LINE_MARGIN_MS = 10.0     # FAILSAFE decided -> its line read by the actuator (pty)
STEADY_S = 0.3            # settled this long before the next injection


@dataclass
class Record:
    fault: str
    required: str
    outcomes: list[Outcome] = field(default_factory=list)
    recover_s: list[float] = field(default_factory=list)
    unrecovered: int = 0
    skipped: str = ""


@dataclass
class RunInfo:
    mode: str
    rounds_planned: int
    rounds_done: int = 0
    seconds: float = 0.0
    link: str = ""
    scheduling: str = "normal"          # of the stack's latency path
    gc_pause_max_ms: float = 0.0        # the harness's longest garbage collection
    stopped_early: str = ""
    unexpected_exits: list[str] = field(default_factory=list)
    runs: list[dict[str, Any]] = field(default_factory=list)   # of a combined table


def bounds_for(brake_toml: Path) -> Bounds:
    s = load_config(brake_toml, BrakeConfig).brake
    return Bounds(failsafe_ms=s.deadline_ms + TIMER_PERIOD_S * 1000 + LINE_MARGIN_MS,
                  watchdog_ms=s.actuator.ttl_ms + 50.0, camera_ms=500.0, frozen_ms=2000.0,
                  unplug_ms=100.0, replug_ms=3000.0, refuse_ms=500.0, recover_s=60.0)


def settled(ctx: Context, timeout_s: float, steady_s: float = STEADY_S) -> bool:
    """Every service up (the launcher's view), the brake armed on fusion's commands,
    fusion saying NONE, the actuator released, all of it for `steady_s` without a break
    (a stack just back may still stumble once)."""
    deadline = time.monotonic() + timeout_s
    sim = ctx.loop.sim
    since: float | None = None
    while time.monotonic() < deadline:
        try:
            running = all(ctx.loop.supervisor.child(s).running() for s in (*SERVICES, "router"))
        except KeyError:
            running = False
        last = ctx.observer.status.last()
        now = time.monotonic_ns()
        fresh = last is not None and now - last.rx_ns < 300_000_000
        targets = ctx.observer.targets.last()
        camera_ok = targets is not None and now - targets.rx_ns < 300_000_000 \
            and targets.msg.verifier_status is VerifierStatus.OK
        if running and fresh and camera_ok and last is not None \
                and last.msg.state is BrakeState.ARMED and sim.settled():
            since = time.monotonic() if since is None else since
            if time.monotonic() - since >= steady_s:
                return True
        else:
            since = None
        time.sleep(0.05)
    return False


class Drive:
    """The SIMULATED ego drives past cars parked beside its lane, over and over, while
    faults are injected: the radar has objects in every cycle (a cycle can be cut in
    its middle), the camera's picture changes (a frozen one can be told), and nothing is
    in the ego's path (fusion says NONE, the brake stays armed)."""

    RUN_S = 8.0

    def __init__(self, sim: Any) -> None:
        import msgspec

        from aeb_radar_camera.tools.sim.scenario import find_scenario, load_scenario
        base = load_scenario(find_scenario("no_threat_parked_cars_30kph"))
        car = base.object[0]
        self.scenario = msgspec.structs.replace(
            base, name="faults_parked_cars_20kph", duration_s=120.0,
            ego=msgspec.structs.replace(base.ego, speed_kph=20.0),
            object=tuple(msgspec.structs.replace(car, x_m=20.0 + 12.0 * i)
                         for i in range(12)))
        self.sim = sim
        self.runs = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="drive", daemon=True)

    def start(self) -> "Drive":
        self._thread.start()
        return self

    def _loop(self) -> None:
        while not self._stop.is_set():
            self.sim.run(self.scenario, timeout_s=self.RUN_S)
            self.runs += 1

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(self.RUN_S + 5.0)


# The harness's threads that stand in for hardware: the simulated world and radar
# (its CAN frames), the actuator, the slcan link. A sensor or an actuator does not wait for
# a CPU; these threads do, and starved by a fault's load they would fail the stack for
# something no vehicle has. Not the main thread (it starts the faults' processes) nor the
# launcher's (it restarts services): a child inherits its parent thread's policy.
SIMULATED_HARDWARE_THREADS = ("sim-loop", "sim-actuator", "slcan-link")
SIMULATED_HARDWARE_BELOW = 10     # priorities under the stack's latency path


def simulated_hardware_at_fifo(priority: int) -> str:
    """The simulated hardware's threads and the harness's Zenoh I/O threads (the world's
    samples) at SCHED_FIFO `priority`; says which, or why not (no root, not Linux)."""
    tids = {t.native_id: t.name for t in threading.enumerate()
            if t.name in SIMULATED_HARDWARE_THREADS and t.native_id is not None}
    tids.update(zenoh_io_threads())
    try:
        for tid in tids:
            set_fifo(priority, tid)
    except (OSError, AttributeError) as exc:
        return f"simulated hardware at normal scheduling ({exc})"
    names = sorted({n.split("-")[0] + "-*" if n.startswith(("rx-", "tx-")) else n
                    for n in tids.values()})
    return f"simulated hardware ({', '.join(names)}) at SCHED_FIFO {priority}"


def _make_link(port: int, kind: str) -> tuple[NetnsLink | RelayLink, str]:
    if kind == "relay":
        return RelayLink(port), "loopback relay (asked for)"
    ns = NetnsLink()
    problem = ns.make()
    if not problem:
        return ns, ""
    return RelayLink(port), f"network namespaces unavailable ({problem}): loopback relay"


def run(out: Path, rounds: int, mode: str, log: IO[str], time_budget_s: float | None = None,
        only: list[str] | None = None, seed: int = 19,
        on_progress: Callable[[str], None] | None = None,
        link_kind: str = "auto",
        stop: threading.Event | None = None,
        skip: list[str] | None = None,
        realtime_priority: int = 0) -> tuple[list[Record], RunInfo]:
    """Start the stack, inject each fault `rounds` times (a round: each fault once, in
    catalogue order), stop. `time_budget_s`: no new round starts after it. `only`:
    faults whose name contains one of these, `skip`: not those. `link_kind`: "auto"
    (network namespaces, else the loopback relay) or "relay". `stop` set: no new
    injection starts, the stack is stopped and what was measured is returned.
    `realtime_priority` > 0: the stack's latency path at SCHED_FIFO, as deployed."""
    stop = stop or threading.Event()
    rng = random.Random(seed)
    faults = [f for f in all_faults() if (only is None or any(o in f.name for o in only))
              and not any(k in f.name for k in skip or [])]
    records = {f.name: Record(f.name, f.required) for f in faults}
    info = RunInfo(mode, rounds)
    if realtime_priority:
        info.scheduling = f"SCHED_FIFO {realtime_priority}"
    port = free_port()
    local = f"tcp/127.0.0.1:{port}"
    link, link_note = _make_link(port, link_kind)
    info.link = link_note or f"network namespace {getattr(link, 'ns', '')} + veth"
    extra_listen = (link.endpoint(port),) if isinstance(link, NetnsLink) else ()

    def adapt(launch: Launch) -> Launch:
        return link.adapt(launch, local, port)

    t_start = time.monotonic()
    say = on_progress or (lambda text: print(text, file=log, flush=True))
    pauses = GcPauses().start()
    try:
        with closed_loop(out, port=port, log=log, restart="always",
                         router_listen=extra_listen, adapt=adapt,
                         realtime_priority=realtime_priority) as loop:
            gate = CanGate(loop.feed.sink)
            loop.feed.sink = gate
            brake_cfg = load_config(Path(out) / "run" / "brake.toml", BrakeConfig).brake
            keys = load_keyring(brake_cfg.command_keys, brake_cfg.instance)
            observer = Observer(loop.bus, loop.actuator, keys)
            drive = Drive(loop.sim).start()
            if realtime_priority:
                info.scheduling += "; " + simulated_hardware_at_fifo(
                    max(1, realtime_priority - SIMULATED_HARDWARE_BELOW))
            # The run's start-up objects (modules, the simulator's scene, the launcher)
            # live as long as the run: out of every later full collection, whose pause
            # holds the GIL and so stalls the simulated radar and actuator threads (as
            # the services do after their own start-up: common/realtime.py).
            gc.collect()
            gc.freeze()
            ctx = Context(loop, observer, bounds_for(Path(out) / "run" / "brake.toml"), rng,
                          gate, link, "")
            if not settled(ctx, 60.0):
                info.stopped_early = "the stack never settled before the first injection"
                return list(records.values()), info
            for r in range(rounds):
                if time_budget_s is not None and time.monotonic() - t_start > time_budget_s:
                    info.stopped_early = (f"time budget of {time_budget_s:.0f} s reached "
                                          f"after {r} rounds")
                    break
                for fault in faults:
                    if stop.is_set():
                        break
                    _one(ctx, fault, records[fault.name], say, r, info)
                if stop.is_set():
                    info.stopped_early = f"stopped by a signal in round {r + 1}"
                    break
                info.rounds_done = r + 1
                say(f"round {r + 1}/{rounds} done ({time.monotonic() - t_start:.0f} s)")
            drive.stop()
    finally:
        link.remove()
        info.seconds = time.monotonic() - t_start
        pauses.stop()
        info.gc_pause_max_ms = pauses.max_ms
    return list(records.values()), info


def _one(ctx: Context, fault: Fault, rec: Record, say: Callable[[str], None], r: int,
         info: RunInfo) -> None:
    problem = fault.available(ctx)
    if problem:
        rec.skipped = problem
        return
    before = _pids(ctx)
    try:
        outcome = fault.inject(ctx)
    except (OSError, KeyError, RuntimeError) as exc:
        outcome = Outcome(False, None, f"injection failed: {exc!r}")
    rec.outcomes.append(outcome)
    t0 = time.monotonic()
    if settled(ctx, ctx.bounds.recover_s):
        rec.recover_s.append(time.monotonic() - t0)
    else:
        rec.unrecovered += 1
        outcome.lost += 1
        outcome.detail += "; the stack did not settle afterwards"
    # a process the fault did not kill that has a new pid died by itself: lost
    killed = getattr(fault, "service", None) if getattr(fault, "sig", None) is \
        signal.SIGKILL else None
    for name, pid in _pids(ctx).items():
        if name != killed and pid != before[name]:
            info.unexpected_exits.append(f"{name} during {fault.name} (round {r + 1})")
            outcome.lost += 1
            outcome.detail += f"; {name} exited unexpectedly"
    resp = "-" if outcome.response_ms is None else f"{outcome.response_ms:.1f} ms"
    say(f"  [{r + 1}] {fault.name}: {'ok' if outcome.ok else 'FAILED'} {resp} "
        f"{outcome.detail}")


def _pids(ctx: Context) -> dict[str, int | None]:
    out: dict[str, int | None] = {}
    for name in (*SERVICES, "router"):
        proc = ctx.loop.supervisor.child(name).proc
        out[name] = None if proc is None else proc.pid
    return out
