"""The multi-process rig of the brake tests: a Zenoh router, the brake service as its own
process, the simulated actuator on a pty in this process, and a bus for observing
BrakeStatus and publishing commands."""

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.command_auth import CommandSigner
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.keys import BRAKE_STATUS, FUSION_BRAKE_CMD
from aeb_radar_camera.common.messages import BrakeCommand, BrakeState, BrakeStatus
from aeb_radar_camera.services.brake.shell import TIMER_PERIOD_S
from aeb_radar_camera.tools.arrivals import Arrivals
from aeb_radar_camera.tools.sim.actuator import SimActuator
from aeb_radar_camera.tools.sim.pty_pair import PtyPair
from tests.brake.helpers import TEST_KEY, write_test_key
from tests.brake.secure import SecureProfile, secure_router
from tests.support import (
    START_TIMEOUT_S,
    HealthWatch,
    ServiceProcess,
    python_module,
    router_process,
)

LIVE = (BrakeState.ARMED, BrakeState.BRAKING)


def toml_text(tables: dict[str, dict[str, Any]]) -> str:
    """A small TOML writer for flat tables (`{"brake": {...}, "brake.serial": {...}}`)."""
    def value(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return f'"{v}"'
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)

    out = []
    for table, fields in tables.items():
        out.append(f"[{table}]")
        out += [f"{k} = {value(v)}" for k, v in fields.items()]
    return "\n".join(out) + "\n"


class Log:
    """Messages in arrival order, each with this process's monotonic arrival time; waits
    that start from an index so that long trial runs stay linear."""

    def __init__(self) -> None:
        self._arrivals: Arrivals[tuple[int, Any]] = Arrivals()

    def __call__(self, msg: Any, key: str) -> None:
        self._arrivals.add((time.monotonic_ns(), msg))

    def __len__(self) -> int:
        return len(self._arrivals)

    @property
    def items(self) -> list[tuple[int, Any]]:
        return self._arrivals.items

    def wait(self, pred: Callable[[Any], bool], timeout_s: float, start: int = 0,
             what: str = "") -> tuple[int, Any]:
        """(index, message) of the first message from `start` on that satisfies `pred`.
        Raises TimeoutError."""
        i, (_, msg) = self._arrivals.wait(lambda item: pred(item[1]), timeout_s, start,
                                          what or "matching message")
        return i, msg

    def since(self, start: int) -> list[Any]:
        return [m for _, m in self._arrivals.since(start)]


@dataclass
class BrakeRig:
    endpoint: str
    log_dir: Path
    link: Path
    sim: SimActuator
    pair: PtyPair
    brake: ServiceProcess
    bus: Bus
    status: Log
    commands: Log          # what the primary publishers put on the bus, as seen here
    deadline_ms: float
    period_ms: float
    secure: SecureProfile | None = None
    realtime_priority: int = 0   # the brake's; the publishers and the router run at it too

    def publisher(self, level: float = 0.0, period_ms: float = 20.0,
                  instance: str = "primary", name: str = "publisher",
                  key: Path | None = None) -> ServiceProcess:
        """A fusion-like process signing with `key` (default: the test key); on the
        secure profile with the certificate of `instance`."""
        zenoh = [] if self.secure is None else ["--zenoh-config", str(self.secure.client(
            "fusion" if instance == "primary" else f"fusion-{instance}"))]
        return ServiceProcess(
            name, python_module("tests.brake.publisher", "--connect", self.endpoint,
                                "--level", str(level), "--period-ms", str(period_ms),
                                "--instance", instance,
                                "--realtime-priority", str(self.realtime_priority),
                                "--key", str(key or write_test_key(self.log_dir)), *zenoh),
            self.log_dir,
        )

    def wait_status(self, pred: Callable[[BrakeStatus], bool], start: int = 0,
                    timeout_s: float = 30.0, what: str = "") -> tuple[int, BrakeStatus]:
        return self.status.wait(pred, timeout_s, start, what)

    def wait_live(self, start: int, level: float = 0.0, timeout_s: float = 30.0,
                  since_ns: int = 0) -> int:
        """Index of the first status from `start` that follows the stream at `level`, on
        a command received after `since_ns` (this host's monotonic clock): a stream that
        just started is not followed while the previous one's session is live."""
        want = BrakeState.BRAKING if level > 0 else BrakeState.ARMED
        i, _ = self.wait_status(
            lambda s: (s.state is want and s.commanded_level_pct == level
                       and s.last_cmd_rx_mono_ns >= since_ns), start, timeout_s,
            f"{want.value} at {level}%")
        return i


@contextmanager
def brake_rig(log_dir: Path, secure: bool = False, watch_commands: bool = True,
              **brake: Any) -> Iterator[BrakeRig]:
    """Everything started and the brake service's liveliness token seen. `brake` holds
    [brake] fields; nested tables as `serial={...}`, `actuator={...}`, `realtime={...}`.
    `secure`: the secure profile (TLS router with access control; this process observes as the
    monitor, which may read everything and write nothing). `watch_commands` false: this
    process does not subscribe to the commands (a flood test: a flood's callbacks would
    take this process's CPU from the simulated actuator it runs).
    `realtime={"priority": p}`: the brake, the router and the publishers at SCHED_FIFO p,
    as deployed (fusion and router at the brake's priority)."""
    nested = {k: brake.pop(k) for k in ("serial", "actuator", "realtime") if k in brake}
    priority = int(nested.get("realtime", {}).get("priority", 0))
    link = log_dir / "actuator"
    brake.setdefault("command_keys", [str(write_test_key(log_dir))])
    tables: dict[str, dict[str, Any]] = {
        "brake": brake,
        "brake.serial": {"port": str(link), **nested.get("serial", {})},
    }
    for table in ("actuator", "realtime"):
        if table in nested:
            tables[f"brake.{table}"] = nested[table]
    config = log_dir / "brake.toml"
    with ExitStack() as stack:
        profile = stack.enter_context(secure_router(log_dir)) if secure else None
        endpoint = profile.endpoint if profile else stack.enter_context(
            router_process(log_dir, realtime_priority=priority))
        if profile is not None:
            tables = {"zenoh": {"config_file": str(profile.client("brake"))}, **tables}
        config.write_text(toml_text(tables))
        sim, pair = SimActuator.on_pty(link, seed=7)
        stack.callback(pair.remove)
        stack.enter_context(sim)
        proc = ServiceProcess("brake", python_module("aeb_radar_camera.services.brake", "--config",
                                                     str(config),
                                                      "--connect", endpoint), log_dir)
        stack.callback(proc.stop)
        bus = stack.enter_context(Bus.open(ZenohSettings(
            mode=ZenohMode.CLIENT, connect=(endpoint,),
            config_file=str(profile.client("monitor")) if profile else ""), "ego", "test"))
        status, commands = Log(), Log()
        bus.subscribe(BRAKE_STATUS, status)
        if watch_commands:
            bus.subscribe(FUSION_BRAKE_CMD, commands, instance="primary")
        watch = HealthWatch(bus)
        try:
            watch.wait_alive("brake", "main", START_TIMEOUT_S)
        except TimeoutError:
            raise AssertionError(f"brake did not start:\n{proc.output()}") from None
        rig = BrakeRig(endpoint, log_dir, link, sim, pair, proc, bus, status, commands,
                       float(brake.get("deadline_ms", 200.0)),
                       TIMER_PERIOD_S * 1000, profile, priority)
        yield rig
        # the test may have replaced the process (a restart): the one running now
        assert rig.brake.alive(), f"brake process died:\n{rig.brake.output()}"
        rig.brake.stop()


@dataclass(frozen=True)
class Received:
    """What the brake took off its command ring between two of its statuses, and what it
    made of it: every sample a command followed, a refusal (by reason) or a failure."""

    samples: int
    followed: int
    refused: dict[str, int]
    failed: int

    @property
    def accounted(self) -> int:
        return self.followed + sum(self.refused.values()) + self.failed


def received(before: BrakeStatus, after: BrakeStatus) -> Received:
    def grew(key: str) -> int:
        return after.counters.get(key, 0) - before.counters.get(key, 0)

    return Received(grew("command_samples"), grew("commands"),
                    {k: v - before.rejected.get(k, 0) for k, v in after.rejected.items()
                     if v != before.rejected.get(k, 0)},
                    grew("command_failed"))


def wait_settled(rig: BrakeRig, count: Callable[[BrakeStatus], int], after_ns: int,
                 start: int, quiet_s: float = 1.0, timeout_s: float = 60.0,
                 what: str = "") -> tuple[int, BrakeStatus]:
    """(index, status) of the first status from `start` on, published `quiet_s` or more
    after `after_ns` (this host's monotonic clock), over whose last `quiet_s` `count` has
    not changed: a sender that finished at `after_ns` has nothing more on its way to the
    brake (what a queue on the way dropped never comes). Raises TimeoutError."""
    last = [-1, 0]

    def quiet(s: BrakeStatus) -> bool:
        n, t = count(s), s.header.pub_mono_ns
        if n != last[0]:
            last[0], last[1] = n, t
        return t - max(last[1], after_ns) >= quiet_s * 1e9

    return rig.wait_status(quiet, start, timeout_s, what or f"no change for {quiet_s:g} s")


def last_command_before(rig: BrakeRig, t_ns: int) -> BrakeCommand | None:
    """The newest primary command this process saw published before `t_ns`."""
    found = None
    for _, msg in rig.commands.items:
        if msg.header.pub_mono_ns <= t_ns:
            found = msg
    return found


class Stream:
    """Primary commands published from this process every `period_ms` on its own thread.
    `inject(fn)` runs `fn(next_seq)` on that thread between two commands (so injected
    samples interleave with the stream deterministically) and returns its result."""

    def __init__(self, bus: Bus, level: float = 0.0, period_ms: float = 20.0) -> None:
        self.pub = bus.publisher(FUSION_BRAKE_CMD, instance="primary")
        self.signer = CommandSigner(TEST_KEY)    # a new session, as a fusion start
        self.started_ns = 0
        self.level = level
        self.period_s = period_ms / 1000
        self.seq = 0
        self.sent: list[BrakeCommand] = []
        self._jobs: list[tuple[Callable[[int], Any], list[Any], threading.Event]] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> "Stream":
        self.started_ns = time.monotonic_ns()
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(5)

    def inject(self, fn: Callable[[int], Any], timeout_s: float = 10.0) -> Any:
        done = threading.Event()
        result: list[Any] = []
        with self._lock:
            self._jobs.append((fn, result, done))
        if not done.wait(timeout_s):
            raise TimeoutError("stream thread did not run the injection")
        return result[0]

    def put(self, msg: BrakeCommand) -> None:
        """Publish `msg` signed in this stream's session."""
        self.pub.put_bytes(self.signer.sign(msg))

    def _run(self) -> None:
        from tests.brake.helpers import command

        while not self._stop.is_set():
            msg = command(self.seq, self.level)
            self.put(msg)
            self.sent.append(msg)
            self.seq += 1
            with self._lock:
                jobs, self._jobs = self._jobs, []
            for fn, result, done in jobs:
                result.append(fn(self.seq))
                done.set()
            self._stop.wait(self.period_s)
