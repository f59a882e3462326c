"""What a Python thread's work costs right after it wakes up, against the same work done
back to back: the machine property behind most of the latency and CPU figures that miss
their targets on a VM like CI's (docs/performance.md).

    python -m benchmarks.wake_penalty [--gap-ms 20] [--n 200]

For each piece of work it prints the median time when run back to back (hot) and when
run right after a sleep of `--gap-ms` (as a service runs after each radar cycle), and
the same after the sleep plus 1 ms of busy-waiting (if the penalty came from the CPU
waking from an idle state, the busy wait would remove it).
"""

import argparse
import sys
import time
from collections.abc import Callable

from common.clock import mono_ns, wall_ns
from common.messages import BrakeCommand, Decision, Header, VerifierStatus, decode, encode
from services.brake.protocol import HostMode, command_line

_INTS = list(range(1000))


def _command() -> bytes:
    return encode(BrakeCommand(
        header=Header(seq=1, source="fusion/primary", stamp_ns=wall_ns(),
                      pub_mono_ns=mono_ns()),
        instance="primary", decision=Decision.NONE, brake_level_pct=0.0,
        verifier_status=VerifierStatus.OK, held=False, track_id=-1, range_m=None,
        ttc_s=None, reason="", radar_seq=1, radar_last_frame_mono_ns=0))


def median_us(fn: Callable[[], object], n: int, gap_s: float, spin_s: float) -> float:
    times = []
    for _ in range(n):
        if gap_s:
            time.sleep(gap_s)
        end = time.perf_counter() + spin_s
        while time.perf_counter() < end:
            pass
        t0 = time.perf_counter_ns()
        fn()
        times.append(time.perf_counter_ns() - t0)
    times.sort()
    return times[len(times) // 2] / 1e3


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.wake_penalty",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--gap-ms", type=float, default=20.0)
    parser.add_argument("--n", type=int, default=200)
    args = parser.parse_args(argv)
    payload = _command()
    work: dict[str, Callable[[], object]] = {
        "empty call": lambda: None,
        "sum of 1000 ints": lambda: sum(_INTS),
        "msgspec decode of a BrakeCommand": lambda: decode(payload, BrakeCommand),
        "actuator command line (CRC-16)": lambda: command_line(7, 50, 250, HostMode.BRAKING),
    }
    gap = args.gap_ms / 1000
    print(f"median of {args.n} runs, microseconds; after a {args.gap_ms:g} ms sleep")
    print(f"{'work':<36}{'hot':>9}{'after sleep':>13}{'+1 ms spin':>12}{'ratio':>8}")
    for name, fn in work.items():
        hot = median_us(fn, args.n, 0.0, 0.0)
        cold = median_us(fn, args.n, gap, 0.0)
        spun = median_us(fn, args.n, gap, 0.001)
        print(f"{name:<36}{hot:>9.1f}{cold:>13.1f}{spun:>12.1f}{cold / hot:>7.1f}x",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
