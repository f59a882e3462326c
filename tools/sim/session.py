"""A closed-loop session: the real stack (router + radar, camera, fusion, brake, each in
its own process, started by the same supervisor as `aeb up`) wired to the SIMULATED
radar link, camera plugin and actuator, plus the simulator driving them.

Used by `aeb demo` and by the benchmarks that measure the stack while scenarios run.
"""

import json
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.net import free_port
from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.tools.launch.supervisor import LinePrinter, Supervisor
from aeb_radar_camera.tools.launch.table import Launch, load_table, resolve_launches
from aeb_radar_camera.tools.sim.radar_feed import RadarFeed
from aeb_radar_camera.tools.sim.runner import SimActuatorView, Simulator
from aeb_radar_camera.tools.sim.scenario import RadarLook
from aeb_radar_camera.tools.sim.stack import (
    FUSION_CONFIG,
    SERVICES,
    TOKENS,
    StackConfigs,
    fusion_instance,
    write_configs,
)

CANDIDATE_CONFIG = DEPLOY / "fusion-candidate.toml"
START_TIMEOUT_S = 120.0
SETTLE_TIMEOUT_S = 60.0


class StackStartError(RuntimeError):
    """The stack did not come up (a service exited or never declared its token)."""


def write_table(folder: Path, endpoint: str, configs: StackConfigs,
                candidate: bool = False, realtime_priority: int = 0,
                restart: str = "never", router_listen: tuple[str, ...] = ()) -> Path:
    """The session's process table (the same launcher as `aeb up`). `restart` is the
    table's restart mode; a process restarted is started again after 0.05 s whatever
    its history (a fault-injection run kills processes on purpose, many times).
    `router_listen`: more endpoints for the router (e.g. on a network namespace's
    link)."""
    listen = json.dumps([endpoint, *router_listen])
    lines = [
        "# Written by the closed-loop session: the stack under simulation.",
        f'workdir = "{folder.resolve()}"', "stop_grace_s = 5.0", "",
        "[router]", f"listen = {listen}", f"realtime_priority = {realtime_priority}", "",
        "[zenoh]", f'connect = ["{endpoint}"]', "",
        "[restart]", f'mode = "{restart}"',
        "backoff = { initial_s = 0.05, max_s = 0.05, factor = 1.0 }", "",
    ]
    for name in SERVICES:
        lines += ["[[service]]", f'name = "{name}"', f'aeb = "{name}"',
                  f'config = "{configs.of(name)}"', ""]
    if candidate:
        lines += ["[[service]]", 'name = "fusion-candidate"', 'aeb = "fusion"',
                  f'config = "{CANDIDATE_CONFIG}"', ""]
    path = folder / "table.toml"
    path.write_text("\n".join(lines))
    return path


def wait_for_stack(bus: Bus, supervisor: Supervisor, timeout_s: float,
                   instance: str = "primary") -> str:
    """Empty once every service's liveliness token is up (fusion's of `instance`), else
    why not."""
    tokens = TOKENS | {"fusion": ("fusion", instance)}
    alive: dict[tuple[str, str], bool] = {}
    lock = threading.Lock()

    def on_health(service: str, instance: str, up: bool) -> None:
        with lock:
            alive[(service, instance)] = up

    bus.subscribe_health(on_health)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with lock:
            missing = [s for s in SERVICES if not alive.get(tokens[s], False)]
        if not missing:
            return ""
        dead = [c.name for c in supervisor.children if c.finished]
        if dead:
            return f"{', '.join(dead)} exited"
        time.sleep(0.05)
    return f"no liveliness token from {', '.join(missing)} within {timeout_s:.0f} s"


def tail(path: Path, n: int = 30) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-n:])
    except OSError:
        return ""


@dataclass
class ClosedLoop:
    """What a running session offers: the bus, the simulator, the radar feed, the
    simulated actuator, the supervisor (service processes: `pid(name)`)."""

    endpoint: str
    bus: Bus
    sim: Simulator
    feed: RadarFeed
    actuator: Any
    supervisor: Supervisor
    log_path: Path

    def pid(self, service: str) -> int:
        proc = self.supervisor.child(service).proc
        if proc is None:
            raise KeyError(f"{service} is not running")
        return proc.pid


@contextmanager
def closed_loop(out: Path, port: int = 0, camera_fps: float = 30.0, candidate: bool = False,
                log: IO[str] | None = None, realtime_priority: int = 0,
                fusion_config: Path = FUSION_CONFIG, raw_can: bool = False,
                restart: str = "never", router_listen: tuple[str, ...] = (),
                adapt: Callable[[Launch], Launch] | None = None) -> Iterator[ClosedLoop]:
    """Start the stack and the simulator; stop everything on exit.

    `restart`, `router_listen`: see write_table. `adapt` may change each process's
    launch before it starts (e.g. run one service in another network namespace).

    `realtime_priority` > 0: SCHED_FIFO for the router and the radar's and brake's
    latency path (tools/sim/stack.py write_configs); fusion's comes from `fusion_config`.
    `raw_can`: the radar also publishes its raw CAN frames (for `aeb record`).

    Service output goes to `out/stack.log`. Raises StackStartError when the stack does
    not come up or never arms, ConfigError for a bad table, BusError / OSError when the
    bus or a pty cannot be opened.
    """
    from aeb_radar_camera.tools.sim.actuator import SimActuator
    from aeb_radar_camera.tools.sim.can_links import SlcanPtyLink

    run_dir = (out / "run").resolve()   # the table and configs name absolute paths
    run_dir.mkdir(parents=True, exist_ok=True)
    log_path = out / "stack.log"
    endpoint = f"tcp/127.0.0.1:{port or free_port()}"
    link = SlcanPtyLink()
    actuator, actuator_pty = SimActuator.on_pty(run_dir / "actuator")
    actuator.start()
    log_file = open(log_path, "w")  # noqa: SIM115 (closed in finally)
    supervisor: Supervisor | None = None
    poller_stop = threading.Event()
    try:
        instance = fusion_instance(fusion_config)
        configs = write_configs(run_dir, endpoint, str(run_dir / "actuator"), link.path,
                                camera_fps=camera_fps, fusion_config=fusion_config,
                                realtime_priority=realtime_priority, raw_can=raw_can,
                                fusion_instance=instance)
        table, workdir = load_table(write_table(run_dir, endpoint, configs, candidate,
                                                realtime_priority, restart, router_listen))
        launches = resolve_launches(table, workdir, "demo")
        if adapt is not None:
            launches = [adapt(launch) for launch in launches]
        supervisor = Supervisor(launches, LinePrinter(
            log_file, ["up", *(launch.name for launch in launches)], colour=False))
        supervisor.start()
        sup = supervisor

        def poll() -> None:
            while not poller_stop.wait(0.1):
                sup.poll()

        threading.Thread(target=poll, name="supervise", daemon=True).start()
        if log is not None:
            print(f"starting router ({endpoint}) and {', '.join(SERVICES)} ...", file=log,
                  flush=True)
        t0 = time.monotonic()
        settings = ZenohSettings(mode=ZenohMode.CLIENT, connect=(endpoint,))
        with Bus.open(settings, "ego", "sim") as bus:
            problem = wait_for_stack(bus, supervisor, START_TIMEOUT_S, instance)
            if problem:
                raise StackStartError(f"the stack did not start: {problem}\n{tail(log_path)}")
            if log is not None:
                print(f"all services up in {time.monotonic() - t0:.1f} s", file=log,
                      flush=True)
            feed = RadarFeed(link, RadarLook())
            sim = Simulator(bus, feed, SimActuatorView(actuator), instance=instance).start()
            try:
                if not sim.wait_settled(SETTLE_TIMEOUT_S):
                    raise StackStartError(
                        f"the stack never armed (fusion {sim.decision or 'silent'}, brake "
                        f"{sim.brake_state or 'silent'})\n{tail(log_path)}")
                yield ClosedLoop(endpoint, bus, sim, feed, actuator, supervisor, log_path)
            finally:
                sim.stop()
    finally:
        poller_stop.set()
        if supervisor is not None:
            supervisor.shutdown()
        link.close()
        actuator.stop()
        actuator_pty.remove()   # no dangling run/actuator link once the pty is gone
        log_file.close()
