"""SIMULATED brake-by-wire actuator: a stand-in for the firmware, for tests and demos.

It is not firmware and drives no hardware. It speaks the host <-> actuator protocol
(docs/actuator-protocol.md) on a serial port: a pseudo-terminal behind a path
(`--pty-link /tmp/aeb/actuator`, what the tests and the demo use) or a real port
(`--port /dev/ttyUSB1`, e.g. one end of a null-modem pair whose other end the brake
service opens; the real actuator's firmware takes its place on a vehicle).

Model: the position follows the commanded level with a first-order response
(time constant `tau_s`); its own watchdog applies its fail-safe (`hold`: keep the last
commanded level, or `release`) when no valid command came for the command's TTL, and
sends fault line 1 (repeated every `fault_repeat_s` while tripped). Lines it cannot use
are answered with a NAK and change nothing.

Faults to inject (thread-safe methods, or control lines on stdin in `aeb sim-actuator`):
no acknowledgement (`set_no_ack`), acknowledgement delay (`set_ack_delay`), garbage on
the line (`inject`, `inject_garbage`, `set_noise`), a fault line with the motor disabled
(`raise_fault` / `clear_fault`), disconnect (`disconnect` / `reconnect`: for a pty the
pair is closed and a new one is made behind the same path).

Reading the brake position (closing the loop in a scenario simulator):
- in-process: `SimActuator.on_pty(path)` then `start()`; poll `position_pct()` (the
  analytic first-order position at the current monotonic time) or `snapshot()`, or
  register `add_listener(callback)`: `callback(SimEvent)` runs on the actuator's thread
  after every applied command, watchdog trip, fault and (dis)connection; keep it short;
- from another process: `aeb sim-actuator --status-file PATH` rewrites PATH atomically
  at `--status-hz` with one JSON object (`SimSnapshot` fields, e.g. `position_pct`,
  `t_mono_ns`, `warning`); the `status` control line prints the same JSON on stdout.

Driven on a simulated clock (the lockstep loop, tools/grid/lockstep.py): `in_memory(clock)`
gives an actuator without a thread on a MemoryEndpoint; `receive(data, now_ns)` hands it
the host's bytes (and runs its watchdog), `endpoint.take()` returns what it wrote.
"""

import argparse
import contextlib
import enum
import json
import logging
import math
import os
import random
import select
import sys
import threading
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Protocol

import serial

from aeb_radar_camera.common.clock import mono_ns
from aeb_radar_camera.common.log import add_log_level, kv, setup_logging
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.services.brake.protocol import (
    FAULT_WATCHDOG,
    Ack,
    ActuatorState,
    BadLine,
    Command,
    Fault,
    HostMode,
    LineReader,
    Nak,
    ProtocolError,
    Query,
    Report,
    decode,
    encode,
    level_to_wire,
)
from aeb_radar_camera.tools.sim.pty_pair import PtyPair

ACTUATOR_ACCEPTS = frozenset("CQ")
# The command lines kept for `commands_since` (about 15 min of a braking host's lines):
# each is two objects the garbage collector walks in every full collection, whose pause
# stalls the process's other threads (the fault harness's simulated radar among them).
HISTORY = 20_000
_log = logging.getLogger("sim_actuator")


class EndpointClosed(Exception):
    """The serial endpoint is gone (closed, unplugged, pty freed)."""


class Endpoint(Protocol):
    def fileno(self) -> int: ...
    def read_available(self) -> bytes: ...
    def write(self, data: bytes) -> None: ...
    def close(self) -> None: ...


class FdEndpoint:
    """A non-blocking file descriptor (a pty master). Writes that would block are dropped:
    a simulated device never stalls because nobody reads it."""

    def __init__(self, fd: int, on_close: Callable[[], None] | None = None) -> None:
        self.fd = fd
        self._on_close = on_close

    def fileno(self) -> int:
        return self.fd

    def read_available(self) -> bytes:
        try:
            data = os.read(self.fd, 4096)
        except BlockingIOError:
            return b""
        except OSError as exc:
            raise EndpointClosed(str(exc)) from exc
        if not data:
            raise EndpointClosed("end of file")
        return data

    def write(self, data: bytes) -> None:
        try:
            os.write(self.fd, data)
        except BlockingIOError:
            pass
        except OSError as exc:
            raise EndpointClosed(str(exc)) from exc

    def close(self) -> None:
        if self._on_close is not None:
            self._on_close()
        else:
            with contextlib.suppress(OSError):
                os.close(self.fd)


class MemoryEndpoint:
    """An endpoint in memory, for an actuator driven without its thread: what the
    actuator writes waits in `take()`; the host's bytes go in through
    `SimActuator.receive`."""

    def __init__(self) -> None:
        self._out = bytearray()

    def fileno(self) -> int:
        return -1

    def read_available(self) -> bytes:
        return b""

    def write(self, data: bytes) -> None:
        self._out += data

    def close(self) -> None:
        pass

    def take(self) -> bytes:
        """Everything written since the last call."""
        out, self._out = bytes(self._out), bytearray()
        return out


class SerialEndpoint:
    """A real serial port through pyserial."""

    def __init__(self, port: str, baudrate: int = 115200) -> None:
        self.port = serial.Serial(port, baudrate, timeout=0, write_timeout=0.05)

    def fileno(self) -> int:
        return int(self.port.fileno())

    def read_available(self) -> bytes:
        try:
            return bytes(self.port.read(self.port.in_waiting or 1))
        except (serial.SerialException, OSError) as exc:
            raise EndpointClosed(str(exc)) from exc

    def write(self, data: bytes) -> None:
        try:
            self.port.write(data)
        except serial.SerialTimeoutException:
            pass
        except (serial.SerialException, OSError) as exc:
            raise EndpointClosed(str(exc)) from exc

    def close(self) -> None:
        with contextlib.suppress(serial.SerialException, OSError):
            self.port.close()


class WatchdogPolicy(enum.Enum):
    HOLD = "hold"          # keep the last commanded level
    RELEASE = "release"    # go to 0


@dataclass(frozen=True, slots=True)
class Received:
    """A command line; `t_ns` is when its bytes were read."""

    t_ns: int
    cmd: Command


@dataclass(frozen=True, slots=True)
class SimEvent:
    t_ns: int
    kind: str              # "command", "watchdog", "fault", "connect", "disconnect"
    position_pct: float
    target_pct: float
    cmd: Command | None = None


@dataclass(frozen=True)
class SimSnapshot:
    t_mono_ns: int
    connected: bool
    position_pct: float
    target_pct: float
    state: str             # OK or FAULT, as in the acknowledgements
    mode: str | None       # the host's last mode letter
    warning: bool          # driver warning lamp: host FAILSAFE/FAULT, own watchdog, fault
    watchdog_tripped: bool
    last_seq: int | None
    commands: int
    acks_sent: int
    naks_sent: int
    watchdog_trips: int
    bad_lines: dict[str, int] = field(default_factory=dict)


class SimActuator:
    """The simulated actuator on one endpoint, served by its own thread (`start`).

    `open_endpoint` is called at start and on every `reconnect()`; it raises OSError or
    serial.SerialException when the port cannot be opened (start() lets it propagate).
    """

    def __init__(
        self,
        open_endpoint: Callable[[], Endpoint],
        *,
        tau_s: float = 0.15,
        watchdog_policy: WatchdogPolicy = WatchdogPolicy.HOLD,
        max_ttl_ms: int = 2000,
        fault_repeat_s: float = 1.0,
        seed: int | None = None,
        clock: Callable[[], int] = mono_ns,
    ) -> None:
        if tau_s <= 0:
            raise ValueError("tau_s must be positive")
        self._open_endpoint = open_endpoint
        self.tau_ns = tau_s * 1e9
        self.watchdog_policy = watchdog_policy
        self.max_ttl_ns = max_ttl_ms * 1_000_000
        self.fault_repeat_ns = round(fault_repeat_s * 1e9)
        self._clock = clock
        self._rng = random.Random(seed)
        self._lock = threading.RLock()
        self._endpoint: Endpoint | None = None
        self._reader = LineReader()
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="sim-actuator", daemon=True)
        self._listeners: list[Callable[[SimEvent], None]] = []
        self._events: list[SimEvent] = []
        # physical model: position(t) = target + (p0 - target) * exp(-(t - t0) / tau)
        self._p0 = 0.0
        self._t0 = clock()
        self._target = 0.0
        self._commanded = 0.0
        # protocol state
        self._last_cmd_ns: int | None = None
        self._ttl_ns = 0
        self._wd_tripped = False
        self._mode: HostMode | None = None
        self._last_seq: int | None = None
        self._fault: Fault | None = None
        self._next_fault_line_ns = 0
        self._pending_acks: deque[tuple[int, bytes]] = deque()
        # injected behaviour
        self._no_ack = False
        self._ack_delay_ns = 0
        self._noise_p = 0.0
        # observation
        self.history: deque[Received] = deque(maxlen=HISTORY)
        self.commands_received = 0      # every command line, also those history let go
        self.bad_lines: Counter[str] = Counter()
        self.acks_sent = 0
        self.naks_sent = 0
        self.watchdog_trips = 0
        self.connects = 0
        self.queries = 0

    @classmethod
    def on_pty(cls, path: str | Path, **kw: Any) -> tuple["SimActuator", PtyPair]:
        """An actuator on a new pty pair behind `path` (the host opens `path`)."""
        pair: PtyPair | None = None

        def open_endpoint() -> Endpoint:
            nonlocal pair
            if pair is None:
                pair = PtyPair(path)
            elif pair.master_fd < 0:
                pair.recreate()
            return FdEndpoint(pair.master_fd, on_close=pair.close)

        sim = cls(open_endpoint, **kw)
        sim._connect()
        assert pair is not None
        return sim, pair

    @classmethod
    def in_memory(cls, clock: Callable[[], int], **kw: Any) -> tuple["SimActuator",
                                                                     MemoryEndpoint]:
        """An actuator on a MemoryEndpoint, connected, on `clock` (ns), for a caller that
        drives it with `receive` and never calls `start`."""
        endpoint = MemoryEndpoint()
        sim = cls(lambda: endpoint, clock=clock, **kw)
        sim._connect()
        return sim, endpoint

    # ---- life cycle -----------------------------------------------------------------

    def start(self) -> "SimActuator":
        with self._lock:
            if self._endpoint is None:
                self._connect()
        self._thread.start()
        return self

    def stop(self) -> None:
        with self._lock:
            self._stop = True
            if self._endpoint is not None:
                self._endpoint.close()
                self._endpoint = None
        self._wake()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
        with self._lock:
            fds, self._wake_r, self._wake_w = (self._wake_r, self._wake_w), -1, -1
        for fd in fds:
            with contextlib.suppress(OSError):
                os.close(fd)

    def __enter__(self) -> "SimActuator":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ---- observation ----------------------------------------------------------------

    def add_listener(self, callback: Callable[[SimEvent], None]) -> None:
        """`callback(event)` after every event, on the thread that caused it (mostly the
        actuator's). It must not raise: an exception ends that thread (a bug of the
        caller, reported by threading.excepthook), and the host sees its acknowledgements
        stop."""
        with self._lock:
            self._listeners.append(callback)

    def position_pct(self, now_ns: int | None = None) -> float:
        with self._lock:
            return self._position(self._clock() if now_ns is None else now_ns)

    def commands_since(self, t_ns: int) -> list[Received]:
        with self._lock:
            return [r for r in self.history if r.t_ns >= t_ns]

    def snapshot(self) -> SimSnapshot:
        with self._lock:
            now = self._clock()
            return SimSnapshot(
                t_mono_ns=now, connected=self._endpoint is not None,
                position_pct=round(self._position(now), 3), target_pct=self._target,
                state=self._state().value, mode=None if self._mode is None else self._mode.value,
                warning=self._warning(), watchdog_tripped=self._wd_tripped,
                last_seq=self._last_seq, commands=self.commands_received, acks_sent=self.acks_sent,
                naks_sent=self.naks_sent, watchdog_trips=self.watchdog_trips,
                bad_lines=dict(self.bad_lines),
            )

    # ---- fault injection --------------------------------------------------------------

    def set_no_ack(self, on: bool) -> None:
        """Apply commands but send no acknowledgement."""
        with self._lock:
            self._no_ack = on

    def set_ack_delay(self, delay_s: float) -> None:
        with self._lock:
            self._ack_delay_ns = round(delay_s * 1e9)
        self._wake()

    def set_noise(self, probability: float) -> None:
        """Before each acknowledgement, with this probability, a burst of garbage."""
        with self._lock:
            self._noise_p = probability

    def inject(self, data: bytes) -> None:
        """Raw bytes onto the line now (dropped when disconnected)."""
        with self._lock:
            self._write(data)

    def inject_garbage(self, n: int = 64) -> bytes:
        """A burst of `n`-ish bytes that must never count as a valid line: random bytes,
        cut-short acknowledgements, acknowledgements with a flipped bit. Returns them."""
        with self._lock:
            data = self._garbage(n)
            self._write(data)
            return data

    def raise_fault(self, code: int, text: str) -> None:
        """Fault: the motor is disabled (position frozen), a fault line now and every
        fault_repeat_s, acknowledgements report FAULT until `clear_fault`."""
        with self._lock:
            now = self._clock()
            self._fault = Fault(code, text)
            self._set_target(self._position(now), now)
            self._next_fault_line_ns = now
            self._emit_fault_line(now)
            self._event(now, "fault")
        self._flush_events()

    def clear_fault(self) -> None:
        with self._lock:
            self._fault = None
            self._set_target(self._commanded, self._clock())

    def disconnect(self) -> None:
        """Close the endpoint: the host's port fails (for a pty: the pair is freed)."""
        with self._lock:
            if self._endpoint is not None:
                self._endpoint.close()
                self._endpoint = None
                self._event(self._clock(), "disconnect")
        self._wake()
        self._flush_events()

    def reconnect(self) -> None:
        """Open a new endpoint (for a pty: a new pair behind the same path)."""
        with self._lock:
            if self._endpoint is None:
                self._connect()
        self._wake()
        self._flush_events()

    # ---- the thread -------------------------------------------------------------------

    def _run(self) -> None:
        while True:
            with self._lock:
                if self._stop:
                    return
                ep = self._endpoint
                timeout = self._timeout(self._clock())
            fds = [self._wake_r] if ep is None else [self._wake_r, ep.fileno()]
            try:
                ready, _, _ = select.select(fds, [], [], timeout)
            except (OSError, ValueError):   # the endpoint was closed under us
                ready = []
            if self._wake_r in ready:
                with contextlib.suppress(OSError):
                    os.read(self._wake_r, 4096)
            data = b""
            read_ns = 0
            if ep is not None and ep.fileno() in ready:
                try:
                    data = ep.read_available()
                    read_ns = self._clock()
                except EndpointClosed as exc:
                    with self._lock:
                        if self._endpoint is ep:
                            ep.close()
                            self._endpoint = None
                            self._event(self._clock(), "disconnect")
                            _log.info(kv("sim_actuator_disconnected", error=exc))
            # Lines take effect when their bytes arrived, not when this thread got the
            # lock from the simulator's: a latency instrument times the line.
            self.receive(data, read_ns or None)

    def receive(self, data: bytes, now_ns: int | None = None) -> None:
        """The host's bytes read at `now_ns` (default: the clock's now), and what is due
        by then (delayed acknowledgements, the watchdog, fault lines): the thread's step,
        also for a caller that drives the actuator on its own clock."""
        with self._lock:
            now = self._clock() if now_ns is None else now_ns
            for item in self._reader.feed(data) if data else ():
                self._handle(item, now)
            self._housekeeping(now)
        self._flush_events()

    def _timeout(self, now: int) -> float:
        due = [now + 100_000_000]
        if self._last_cmd_ns is not None and not self._wd_tripped:
            due.append(self._last_cmd_ns + self._ttl_ns)
        if self._fault is not None or self._wd_tripped:
            due.append(self._next_fault_line_ns)
        if self._pending_acks:
            due.append(self._pending_acks[0][0])
        return max(0.0, (min(due) - now) / 1e9)

    def _housekeeping(self, now: int) -> None:
        while self._pending_acks and self._pending_acks[0][0] <= now:
            self._write(self._pending_acks.popleft()[1])
        if (self._last_cmd_ns is not None and not self._wd_tripped
                and now - self._last_cmd_ns >= self._ttl_ns):
            self._wd_tripped = True
            self.watchdog_trips += 1
            if self.watchdog_policy is WatchdogPolicy.RELEASE and self._fault is None:
                self._set_target(0.0, now)
            self._next_fault_line_ns = now
            self._event(now, "watchdog")
        if (self._fault is not None or self._wd_tripped) and now >= self._next_fault_line_ns:
            self._emit_fault_line(now)

    def _handle(self, item: bytes | BadLine, now: int) -> None:
        if isinstance(item, BadLine):
            self.bad_lines[item.value] += 1
            if item is BadLine.LENGTH:
                self._nak(None, item)
            return
        try:
            frame = decode(item, ACTUATOR_ACCEPTS)
        except ProtocolError as exc:
            self.bad_lines[exc.reason.value] += 1
            self._nak(None, exc.reason)
            return
        pos = min(100.0, max(0.0, round(self._position(now), 1)))
        if isinstance(frame, Query):
            # what it holds, changing nothing: not the target, not the watchdog
            self.queries += 1
            self._write(encode(Report(level_to_wire(self._target), pos, self._state())))
            return
        assert isinstance(frame, Command)
        self._last_cmd_ns = now
        self._ttl_ns = min(frame.ttl_ms * 1_000_000, self.max_ttl_ns)
        self._wd_tripped = False
        self._mode = frame.mode
        self._last_seq = frame.seq
        self._commanded = float(frame.level_pct)
        if self._fault is None:
            self._set_target(self._commanded, now)
        self.history.append(Received(now, frame))
        self.commands_received += 1
        self._event(now, "command", frame)
        if self._no_ack:
            return
        if self._noise_p and self._rng.random() < self._noise_p:
            self._write(self._garbage(self._rng.randint(1, 48)))
        pos = min(100.0, max(0.0, round(self._position(now), 1)))   # after the new target
        line = encode(Ack(frame.seq, pos, self._state()))
        self.acks_sent += 1
        if self._ack_delay_ns:
            self._pending_acks.append((now + self._ack_delay_ns, line))
        else:
            self._write(line)

    # ---- helpers (lock held) ------------------------------------------------------------

    def _connect(self) -> None:
        self._endpoint = self._open_endpoint()
        self._reader = LineReader()
        self.connects += 1
        self._event(self._clock(), "connect")

    def _position(self, now: int) -> float:
        dt = max(0, now - self._t0)
        return self._target + (self._p0 - self._target) * math.exp(-dt / self.tau_ns)

    def _set_target(self, target: float, now: int) -> None:
        self._p0 = self._position(now)
        self._t0 = now
        self._target = target

    def _state(self) -> ActuatorState:
        return ActuatorState.OK if self._fault is None else ActuatorState.FAULT

    def _warning(self) -> bool:
        return (self._fault is not None or self._wd_tripped
                or self._mode in (HostMode.FAILSAFE, HostMode.FAULT))

    def _emit_fault_line(self, now: int) -> None:
        fault = self._fault or Fault(FAULT_WATCHDOG, "watchdog ttl expired")
        self._write(encode(fault))
        self._next_fault_line_ns = now + self.fault_repeat_ns

    def _nak(self, seq: int | None, reason: BadLine) -> None:
        self.naks_sent += 1
        self._write(encode(Nak(seq, reason)))

    def _write(self, data: bytes) -> None:
        ep = self._endpoint
        if ep is None:
            return
        # a failed write shows up on the read side too, which reports the disconnect
        with contextlib.suppress(EndpointClosed):
            ep.write(data)

    def _garbage(self, n: int) -> bytes:
        rng = self._rng
        real = encode(Ack(rng.randrange(0, 1000), 12.3, ActuatorState.OK))
        pieces: list[bytes] = []
        while sum(map(len, pieces)) < n:
            kind = rng.randrange(4)
            if kind == 0:
                pieces.append(rng.randbytes(rng.randint(1, 16)))
            elif kind == 1:
                pieces.append(real[:rng.randint(1, len(real) - 2)])   # cut short
            elif kind == 2:
                flipped = bytearray(real)
                i = rng.randrange(1, len(real) - 1)
                flipped[i] ^= 1 << rng.randrange(8)
                pieces.append(bytes(flipped))                      # CRC catches one bit
            else:
                pieces.append(rng.choice([b"$", b"\n", b"\r\n", b"*", b"$A,1,", b",,,"]))
        return b"".join(pieces)

    def _event(self, now: int, kind: str, cmd: Command | None = None) -> None:
        if self._listeners:
            self._events.append(SimEvent(now, kind, self._position(now), self._target, cmd))

    def _flush_events(self) -> None:
        with self._lock:
            events, self._events = self._events, []
            listeners = list(self._listeners)
        for ev in events:
            for cb in listeners:
                cb(ev)

    def _wake(self) -> None:
        with self._lock:   # never a write to a closed (and maybe reused) descriptor
            if self._wake_w >= 0:
                with contextlib.suppress(OSError):
                    os.write(self._wake_w, b"x")


# ---- the process: `aeb sim-actuator` ---------------------------------------------------

CONTROL_HELP = """control lines (stdin): noack on|off, delay MS, garbage [N], noise P,
fault CODE [TEXT], clear, disconnect, reconnect, status, quit"""


def control(sim: SimActuator, line: str) -> str:
    """Apply one control line; returns the reply. Raises ValueError on a bad line."""
    words = line.split()
    if not words:
        return ""
    cmd, args = words[0].lower(), words[1:]
    if cmd == "noack" and args and args[0] in ("on", "off"):
        sim.set_no_ack(args[0] == "on")
    elif cmd == "delay" and len(args) == 1:
        sim.set_ack_delay(float(args[0]) / 1000)
    elif cmd == "garbage" and len(args) <= 1:
        sim.inject_garbage(int(args[0]) if args else 64)
    elif cmd == "noise" and len(args) == 1:
        sim.set_noise(float(args[0]))
    elif cmd == "fault" and args:
        sim.raise_fault(int(args[0]), " ".join(args[1:]) or "injected")
    elif cmd == "clear" and not args:
        sim.clear_fault()
    elif cmd == "disconnect" and not args:
        sim.disconnect()
    elif cmd == "reconnect" and not args:
        sim.reconnect()
    elif cmd == "status" and not args:
        return json.dumps(asdict(sim.snapshot()))
    else:
        raise ValueError(f"unknown control line {line.strip()!r}; {CONTROL_HELP}")
    return "ok"


def _write_status_file(path: Path, sim: SimActuator) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(asdict(sim.snapshot())) + "\n")
    os.replace(tmp, path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="aeb sim-actuator",
        description="SIMULATED brake actuator speaking docs/actuator-protocol.md "
                    "(not firmware, drives no hardware). " + CONTROL_HELP,
    )
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--pty-link", help="create a pty and a symlink at this path for the host")
    where.add_argument("--port", help="serve on this real serial port")
    parser.add_argument("--baudrate", type=int, default=115200)
    parser.add_argument("--tau-s", type=float, default=0.15, help="position time constant")
    parser.add_argument("--watchdog-policy", choices=[p.value for p in WatchdogPolicy],
                        default=WatchdogPolicy.HOLD.value)
    parser.add_argument("--status-file", help="rewrite this JSON file with the position")
    parser.add_argument("--status-hz", type=float, default=50.0)
    parser.add_argument("--no-control", action="store_true", help="ignore stdin")
    parser.add_argument("--seed", type=int, help="seed of the garbage generator")
    add_log_level(parser, "INFO")
    args = parser.parse_args(argv)
    log = setup_logging("sim_actuator", args.log_level)
    kw: dict[str, Any] = dict(tau_s=args.tau_s, seed=args.seed,
                              watchdog_policy=WatchdogPolicy(args.watchdog_policy))
    pair: PtyPair | None = None
    try:
        if args.pty_link:
            sim, pair = SimActuator.on_pty(args.pty_link, **kw)
            where_desc = f"{args.pty_link} -> {pair.slave_name}"
        else:
            port, baud = args.port, args.baudrate
            sim = SimActuator(lambda: SerialEndpoint(port, baud), **kw)
            where_desc = port
        sim.start()
    except (OSError, serial.SerialException, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    stop = stop_event_on_signals()
    log.info(kv("sim_actuator_ready", port=where_desc, simulated=True))
    print(f"ready {args.pty_link or args.port}", flush=True)
    if not args.no_control:
        threading.Thread(target=_control_loop, args=(sim, stop), daemon=True).start()
    status_path = Path(args.status_file) if args.status_file else None
    period = 1.0 / args.status_hz if args.status_hz > 0 else 1.0
    while not stop.wait(period if status_path else 1.0):
        if status_path is not None:
            _write_status_file(status_path, sim)
    sim.stop()
    if pair is not None:
        pair.remove()
    log.info(kv("sim_actuator_stopped"))
    return 0


def _control_loop(sim: SimActuator, stop: threading.Event) -> None:
    """Control lines from stdin; `quit` stops the process, end of input does not."""
    for line in sys.stdin:
        if line.strip().lower() == "quit":
            stop.set()
            return
        try:
            reply = control(sim, line)
        except ValueError as exc:
            reply = f"error: {exc}"
        if reply:
            print(reply, flush=True)


if __name__ == "__main__":
    sys.exit(main())
