"""Brake benchmark: BrakeCommand receipt to bytes on the serial line.

    python -m benchmarks.bench_brake [--quick] [--out out/bench] [--count N] [--rate-hz R]

Starts a Zenoh router and the brake service
(`python -m aeb_radar_camera.services.brake`) as their own
processes; the SIMULATED actuator (tools/sim/actuator.py) runs in this process
on a pty and timestamps every line it reads. This process publishes BrakeCommands at
`--rate-hz` (BRAKE at 50% once armed), then measures, for each command:

- receipt -> serial write, as the service measures it (`BrakeStatus.cmd_to_serial_us`:
  from the start of the Zenoh callback to the return of the write);
- publish -> line read by the actuator (end to end, same host, monotonic clock).

Baseline in the same run, interleaved (half a period after each brake command): a relay
process that subscribes to another instance's command key and writes a fixed line to
its own pty in the Zenoh callback (no decoding, validation, state or lock): the raw
Zenoh hop plus the pty write. Its publish -> line-read times compare directly with the
brake's end-to-end row. (The brake service sees the relay's samples too and counts them
as `wrong_instance`, as it would a shadow-mode candidate.)

Prints a table (p50, p99, max), writes bench_brake.json and bench_brake.png (histograms)
under --out.
"""

import argparse
import json
import os
import select
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.command_auth import CommandSigner, new_key, write_key
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.keys import BRAKE_STATUS, FUSION_BRAKE_CMD
from aeb_radar_camera.common.messages import (
    BrakeCommand,
    BrakeStatus,
    Decision,
    Header,
    VerifierStatus,
)
from aeb_radar_camera.common.net import free_port, wait_listening
from aeb_radar_camera.services.brake.shell import TIMER_PERIOD_S
from aeb_radar_camera.tools.sim.actuator import SimActuator
from aeb_radar_camera.tools.sim.pty_pair import PtyPair
from benchmarks.figures import Figure
from benchmarks.processes import stop_processes

WARMUP = 20
KEY = new_key("primary")   # this run's command key, given to the brake in its config
BASELINE_INSTANCE = "bench"


@dataclass
class Row:
    name: str
    values_us: list[float]

    def pct(self, q: float) -> float:
        v = sorted(self.values_us)
        return v[min(len(v) - 1, round(q * (len(v) - 1)))]


def _command(seq: int, instance: str, level: float) -> BrakeCommand:
    now = mono_ns()
    return BrakeCommand(
        header=Header(seq=seq, source=f"fusion/{instance}", stamp_ns=wall_ns(), pub_mono_ns=now),
        instance=instance, decision=Decision.BRAKE if level else Decision.NONE,
        brake_level_pct=level, verifier_status=VerifierStatus.OK, held=False,
        track_id=1 if level else -1, range_m=8.0 if level else None,
        ttc_s=1.0 if level else None, reason="bench", radar_seq=seq,
        radar_last_frame_mono_ns=now,
    )


def _publish(bus: Bus, count: int, rate_hz: float) -> tuple[list[int], list[int]]:
    """`count` commands to the brake (5 NONE to arm, then BRAKE 50%) and, half a period
    later each time, the same to the baseline relay, each signed as fusion signs them;
    their publish times."""
    signer = CommandSigner(KEY)
    brake = bus.publisher(FUSION_BRAKE_CMD, instance="primary")
    relay = bus.publisher(FUSION_BRAKE_CMD, instance=BASELINE_INSTANCE)
    brake_ns: list[int] = []
    relay_ns: list[int] = []
    half = 0.5 / rate_hz
    next_t = time.monotonic()
    for seq in range(count):
        level = 0.0 if seq < 5 else 50.0
        for pub, instance, times in ((brake, "primary", brake_ns),
                                     (relay, BASELINE_INSTANCE, relay_ns)):
            msg = _command(seq, instance, level)
            pub.put_bytes(signer.sign(msg))
            times.append(msg.header.pub_mono_ns)
            next_t += half
            time.sleep(max(0.0, next_t - time.monotonic()))
    return brake_ns, relay_ns


def _match(pub_ns: list[int], read_ns: list[int]) -> list[float]:
    """For each publish, the first line read after it and before the next publish."""
    out: list[float] = []
    j = 0
    for i, p in enumerate(pub_ns):
        nxt = pub_ns[i + 1] if i + 1 < len(pub_ns) else None
        while j < len(read_ns) and read_ns[j] < p:
            j += 1
        if j < len(read_ns) and (nxt is None or read_ns[j] < nxt):
            out.append((read_ns[j] - p) / 1e3)
    return out


class LineTimes:
    """Read a pty master, timestamping each complete line (the baseline's receiver)."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.times: list[int] = []
        self._stop = False
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop:
            ready, _, _ = select.select([self.fd], [], [], 0.1)
            if not ready:
                continue
            try:
                data = os.read(self.fd, 4096)
            except BlockingIOError:
                continue
            except OSError:
                return
            t = mono_ns()
            self.times.extend(t for _ in range(data.count(b"\n")))

    def stop(self) -> None:
        self._stop = True
        self._thread.join(2)


def relay_main(endpoint: str, port: str) -> int:
    """The baseline: Zenoh callback -> fixed line on a pty, nothing else."""
    import serial

    line = b"$C,1,0,50,250,B*0000\n"
    ser = serial.Serial(port, 115200, timeout=0.05, write_timeout=0.02)
    fd = ser.fd
    settings = ZenohSettings(mode=ZenohMode.CLIENT, connect=(endpoint,))

    def relay(payload: bytes, key: str, rx_mono_ns: int) -> None:
        os.write(fd, line)

    # the brake service's timer wakes at least every TIMER_PERIOD_S (50 ms); the same
    # here, so that both processes run under the same conditions (a process that sleeps
    # longer wakes up slower)
    stop = threading.Event()

    def idle_timer() -> None:
        while not stop.wait(TIMER_PERIOD_S):
            pass

    threading.Thread(target=idle_timer, daemon=True).start()
    with Bus.open(settings, "ego", "bench/relay") as bus:
        bus.subscribe_raw(FUSION_BRAKE_CMD, relay, instance=BASELINE_INSTANCE)
        bus.declare_health("bench-relay", "main")
        sys.stdin.read()              # until the benchmark closes our stdin
    return 0


def _health(bus: Bus, service: str) -> threading.Event:
    seen = threading.Event()

    def on(svc: str, instance: str, alive: bool) -> None:
        if svc == service and alive:
            seen.set()

    bus.subscribe_health(on)
    return seen


def measure(count: int, rate_hz: float, work: Path) -> list[Row]:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    procs: list[subprocess.Popen[bytes]] = []
    log = open(work / "processes.log", "wb")  # noqa: SIM115 (closed below)
    sim, pair = SimActuator.on_pty(work / "actuator")
    relay_pty = PtyPair(work / "relay")
    try:
        procs.append(subprocess.Popen([sys.executable, "-m", "aeb_radar_camera.common.router",
                                       "--listen",
                                       endpoint], stdout=log, stderr=log))
        wait_listening(port, 60)
        config = work / "brake.toml"
        write_key(work / "primary.key", KEY)
        config.write_text(f'[brake]\ndeadline_ms = 1000.0\nmax_age_ms = 1000.0\n'
                          f'command_keys = ["{work / "primary.key"}"]\n[brake.serial]\n'
                          f'port = "{work / "actuator"}"\n')
        sim.start()
        procs.append(subprocess.Popen([sys.executable, "-m", "aeb_radar_camera.services.brake",
                                       "--config",
                                       str(config), "--connect", endpoint],
                                      stdout=log, stderr=log))
        settings = ZenohSettings(mode=ZenohMode.CLIENT, connect=(endpoint,))
        with Bus.open(settings, "ego", "bench") as bus:
            brake_up = _health(bus, "brake")
            relay_up = _health(bus, "bench-relay")
            statuses: list[BrakeStatus] = []
            bus.subscribe(BRAKE_STATUS, lambda msg, key: statuses.append(msg))
            if not brake_up.wait(60):
                raise RuntimeError("the brake service did not start (see processes.log)")
            relay = subprocess.Popen([sys.executable, "-m", "benchmarks.bench_brake",
                                      "--relay", endpoint, str(work / "relay")],
                                     stdin=subprocess.PIPE, stdout=log, stderr=log)
            procs.append(relay)
            if not relay_up.wait(60):
                raise RuntimeError("the baseline relay did not start (see processes.log)")
            reader = LineTimes(relay_pty.master_fd)
            t0 = mono_ns()
            brake_pub, relay_pub = _publish(bus, count, rate_hz)
            time.sleep(0.3)
            reader.stop()
            assert relay.stdin is not None
            relay.stdin.close()
            read_ns = [r.t_ns for r in sim.commands_since(t0)]
            by_seq: dict[int, float] = {}
            for st in statuses:
                if st.cmd_to_serial_us is not None and st.header.pub_mono_ns > t0:
                    by_seq.setdefault(st.last_cmd_seq, st.cmd_to_serial_us)
            service = [v for seq, v in sorted(by_seq.items()) if seq >= WARMUP]
            brake_e2e = _match(brake_pub, read_ns)[WARMUP:]
            baseline = _match(relay_pub, [t for t in reader.times if t >= t0])[WARMUP:]
    finally:
        stop_processes(reversed(procs))
        log.close()
        sim.stop()
        pair.remove()
        relay_pty.remove()
    return [
        Row("brake: command receipt -> serial write (service)", service),
        Row("brake: publish -> line read by the actuator", brake_e2e),
        Row("baseline: publish -> relay (no checks) -> line read", baseline),
    ]


def table(rows: list[Row], count: int, rate_hz: float) -> str:
    lines = [f"brake: {count} commands at {rate_hz:g} Hz; SIMULATED actuator on a pty; "
             "times in us",
             f"{'path':<54}{'n':>6}{'p50':>9}{'p99':>9}{'max':>9}"]
    for r in rows:
        if not r.values_us:
            lines.append(f"{r.name:<54}{0:>6}{'-':>9}{'-':>9}{'-':>9}")
            continue
        lines.append(f"{r.name:<54}{len(r.values_us):>6}{r.pct(0.5):>9.0f}"
                     f"{r.pct(0.99):>9.0f}{max(r.values_us):>9.0f}")
    return "\n".join(lines)


def plot(rows: list[Row], out: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(9, 4.5))
    vals = [v for r in rows for v in r.values_us]
    hi = float(np.percentile(vals, 99.5)) if vals else 1.0
    bins = np.linspace(0, hi, 80).tolist()
    for r in rows:
        if r.values_us:
            ax.hist(np.clip(r.values_us, 0, hi), bins=bins, alpha=0.55,
                    label=f"{r.name} (p50 {r.pct(0.5):.0f}, p99 {r.pct(0.99):.0f} us)")
    ax.set_xlabel("latency (us), clipped at p99.5")
    ax.set_ylabel("commands")
    ax.set_title("Brake: command to serial line (simulated actuator on a pty)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = out / "bench_brake.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def figures(rows: list[Row]) -> list[Figure]:
    """Suite figures: the service's own receipt->write time, and the end-to-end time beside
    the raw relay measured interleaved in the same run."""
    service, e2e, baseline = rows
    out: list[Figure] = []
    for q, label in ((0.5, "p50"), (0.99, "p99")):
        if service.values_us:
            out.append(Figure("brake", f"command receipt -> serial write {label}",
                              service.pct(q), "us",
                              note="measured in the service (BrakeStatus.cmd_to_serial_us)"))
        if e2e.values_us:
            out.append(Figure(
                "brake", f"publish -> actuator line read {label}", e2e.pct(q), "us",
                baseline="bare relay: publish -> pty line, no checks",
                baseline_value=baseline.pct(q) if baseline.values_us else None,
                note="SIMULATED actuator on a pty"))
    return out


def run(quick: bool, out_dir: Path, rate_hz: float = 50.0) -> list[Figure]:
    """The suite's entry: measure, write bench_brake.png under `out_dir`, return figures."""
    count = 300 if quick else 2000
    with tempfile.TemporaryDirectory(prefix="bench_brake_") as tmp:
        rows = measure(count, rate_hz, Path(tmp))
    print(table(rows, count, rate_hz), flush=True)
    plot(rows, out_dir)
    return figures(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="bench_brake", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="300 commands instead of 2000")
    parser.add_argument("--count", type=int, help="commands per run")
    parser.add_argument("--rate-hz", type=float, default=50.0)
    parser.add_argument("--out", default="out/bench")
    parser.add_argument("--relay", nargs=2, metavar=("ENDPOINT", "PORT"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.relay:
        return relay_main(*args.relay)
    count = args.count or (300 if args.quick else 2000)
    if count <= WARMUP + 10:
        parser.error(f"--count must be above {WARMUP + 10}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="bench_brake_") as tmp:
        rows = measure(count, args.rate_hz, Path(tmp))
    print(table(rows, count, args.rate_hz))
    png = plot(rows, out)
    (out / "bench_brake.json").write_text(json.dumps({
        "count": count, "rate_hz": args.rate_hz,
        "rows": {r.name: {"n": len(r.values_us), "p50_us": r.pct(0.5) if r.values_us else None,
                          "p99_us": r.pct(0.99) if r.values_us else None}
                 for r in rows},
    }, indent=2))
    print(f"wrote {png} and {out / 'bench_brake.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
