"""What a stuck subscriber does to the brake's command stream (docs/security.md).

A router, a command stream at fusion's rate on the brake's key (the registry's QoS, or
the congestion control given), a receiver of those commands as the brake is one (a
client of the router), camera-sized samples on the camera key (a process of its own:
`stuck.py --load`), and a **simulated**
stuck subscriber of ``aeb/<vehicle>/**`` (tools/faults/stuck.py) that is frozen with
SIGSTOP (or whose callback blocks, `--block`) once it is subscribed. The camera samples
fill its link's receive buffer within seconds, as a real camera's do; after that the
router can deliver nothing more to it.

    python -m benchmarks.bench_stuck_subscriber [--congestion BLOCK|DROP] [--observe-s 8]

Prints the widest gap between two commands the receiver got, how many it never got (by
sequence number) and the longest `put` of the command publisher, before the freeze and
from the freeze until `--observe-s` after the stuck subscriber's receive queue stopped
growing, then one JSON line. Exit code 0 when it ran, 1 when a helper process did not
start.
"""

import argparse
import dataclasses
import itertools
import json
import signal
import subprocess
import sys
import threading
import time

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.keys import FUSION_BRAKE_CMD, Congestion
from aeb_radar_camera.common.net import free_port, port_open
from aeb_radar_camera.tools.faults.stuck import wait_filled
from benchmarks.processes import stop_processes

VEHICLE = "ego"
# a BrakeCommand's size on the bus (benchmarks/floor_relay.py command_size: ~200 B)
COMMAND_BYTES = 200


class Stream:
    """Commands published every `period_s` on their own thread; each put's duration."""

    def __init__(self, bus: Bus, congestion: Congestion | None, period_s: float) -> None:
        spec = FUSION_BRAKE_CMD
        if congestion is not None:
            spec = dataclasses.replace(spec, qos=dataclasses.replace(spec.qos,
                                                                     congestion=congestion))
        self.qos = spec.qos
        self.pub = bus.publisher(spec, instance="primary")
        self.period_s = period_s
        self.puts: list[tuple[int, int]] = []       # (start, duration) ns
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, name="commands", daemon=True)

    def _run(self) -> None:
        seq = 0
        next_t = time.monotonic()
        while not self.stop.is_set():
            t0 = time.monotonic_ns()
            # the sequence number first: the receiver tells a lost command from a late one
            self.pub.put_bytes(seq.to_bytes(8, "big") + bytes(COMMAND_BYTES - 8))
            seq += 1
            self.puts.append((t0, time.monotonic_ns() - t0))
            next_t = max(next_t + self.period_s, time.monotonic())
            self.stop.wait(next_t - time.monotonic())


def widest_gap_ms(arrivals: list[int], t0: int, t1: int) -> float:
    """The widest interval between consecutive arrivals in [t0, t1], its ends included
    (no arrival at all: the whole window)."""
    inside = [t0, *[t for t in arrivals if t0 <= t <= t1], t1]
    return max(b - a for a, b in itertools.pairwise(inside)) / 1e6


def longest_put_ms(puts: list[tuple[int, int]], t0: int, t1: int) -> float:
    return max((d for t, d in puts if t0 <= t <= t1), default=0) / 1e6


def client(endpoint: str) -> Bus:
    return Bus.open(ZenohSettings(mode=ZenohMode.CLIENT, connect=(endpoint,)), VEHICLE,
                    "bench")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_stuck_subscriber",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--congestion", choices=[c.value for c in Congestion],
                        help="the command key's congestion control (default: the registry's)")
    parser.add_argument("--period-ms", type=float, default=75.0)
    parser.add_argument("--baseline-s", type=float, default=2.0)
    parser.add_argument("--observe-s", type=float, default=8.0)
    parser.add_argument("--router-config", default="",
                        help="a Zenoh JSON5 file for the router (e.g. other drop waits)")
    parser.add_argument("--block", action="store_true",
                        help="a callback that blocks instead of SIGSTOP")
    args = parser.parse_args(argv)
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router = subprocess.Popen([sys.executable, "-m", "aeb_radar_camera.common.router",
                               "--listen", endpoint,
                               *(["--config-file", args.router_config]
                                 if args.router_config else [])], stdout=subprocess.DEVNULL)
    stuck: subprocess.Popen[str] | None = None
    load: subprocess.Popen[str] | None = None
    try:
        deadline = time.monotonic() + 30
        while not port_open(port):
            if time.monotonic() > deadline or router.poll() is not None:
                print("error: the router did not start", file=sys.stderr)
                return 1
            time.sleep(0.05)
        with client(endpoint) as rx_bus, client(endpoint) as tx_bus:
            arrivals: list[int] = []
            seqs: list[int] = []

            def on_command(payload: bytes, key: str, t_ns: int) -> None:
                arrivals.append(t_ns)
                seqs.append(int.from_bytes(payload[:8], "big"))

            sub = rx_bus.subscribe_raw(FUSION_BRAKE_CMD, on_command, instance="primary")
            stream = Stream(tx_bus, Congestion(args.congestion) if args.congestion else None,
                            args.period_ms / 1000)
            stream.thread.start()
            # ready once the commands reach it
            stuck = subprocess.Popen([sys.executable, "-m",
                                      "aeb_radar_camera.tools.faults.stuck", "--connect",
                                      endpoint, *(["--block"] if args.block else [])],
                                     stdout=subprocess.PIPE, text=True)
            assert stuck.stdout is not None
            if stuck.stdout.readline().strip() != "ready":
                print("error: the stuck subscriber did not start", file=sys.stderr)
                return 1
            time.sleep(args.baseline_s)       # the measurement's own duration
            t_freeze = time.monotonic_ns()
            if not args.block:
                stuck.send_signal(signal.SIGSTOP)
            # the load from a process of its own: it takes no time of this one's receiver
            load = subprocess.Popen([sys.executable, "-m", "aeb_radar_camera.tools.faults.stuck",
                                     "--connect", endpoint, "--load"], stdout=subprocess.PIPE,
                                    text=True)
            assert load.stdout is not None
            # the queues judged full only once the load runs (the commands alone would
            # leave them unchanged)
            if load.stdout.readline().strip() != "ready":
                print("error: the load did not start", file=sys.stderr)
                return 1
            filled, fill_s = wait_filled(stuck.pid, 60.0, router=router.pid)
            t_full = time.monotonic_ns()
            time.sleep(args.observe_s)        # the measurement's own duration
            t_end = time.monotonic_ns()
            stream.stop.set()
            stream.thread.join(10)
            sub.undeclare()
            base_gap = widest_gap_ms(arrivals, t_freeze - int(args.baseline_s * 0.8e9),
                                     t_freeze)
            base_put = longest_put_ms(stream.puts, t_freeze - int(args.baseline_s * 0.8e9),
                                      t_freeze)
            # from the freeze: the router may stall before the queue is seen to be full
            gap = widest_gap_ms(arrivals, t_freeze, t_end)
            put = longest_put_ms(stream.puts, t_freeze, t_end)
            got = sum(1 for t in arrivals if t_full <= t <= t_end)
            during = [q for t, q in zip(arrivals, seqs, strict=True) if t_freeze <= t <= t_end]
            lost = (max(during) - min(during) + 1 - len(set(during))) if during else 0
    finally:
        if stuck is not None and stuck.poll() is None:
            stuck.send_signal(signal.SIGCONT)
        stop_processes([load, stuck, router])
    mode = "callback blocks" if args.block else "SIGSTOP"
    print(f"command key {stream.qos.congestion.value} {stream.qos.priority.value}"
          f"{' express' if stream.qos.express else ''}, period {args.period_ms:.0f} ms, "
          f"stuck subscriber of aeb/{VEHICLE}/** ({mode}), {filled / 1e6:.1f} MB unread "
          f"after {fill_s:.1f} s")
    print(f"  before: widest gap {base_gap:.1f} ms, longest put {base_put:.1f} ms")
    print(f"  from the freeze to {args.observe_s:.0f} s after its queue was full: widest gap "
          f"{gap:.1f} ms, longest put {put:.1f} ms; {got} commands received after the fill, "
          f"{lost} lost from the freeze on")
    print(json.dumps({"congestion": stream.qos.congestion.value, "mode": mode,
                      "period_ms": args.period_ms, "unread_bytes": filled,
                      "fill_s": round(fill_s, 2), "baseline_gap_ms": round(base_gap, 1),
                      "baseline_put_ms": round(base_put, 1), "gap_ms": round(gap, 1),
                      "put_ms": round(put, 1), "received": got, "lost": lost}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
