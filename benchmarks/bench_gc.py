"""The garbage collector's pause for a history of decoded messages.

    python -m benchmarks.bench_gc [--history N] [--repeat R]

A process that keeps thousands of decoded messages (a monitor's history, the fault
harness's observer, a recording's index) pays for them in every full collection: a
pause that holds the GIL for every thread of the process, its real-time ones included.
Messages are declared ``gc=False`` (common/messages/__init__.py). Measured in one run,
each a full `gc.collect()` R times (median and max, ms) with N each of VerifiedTargets
(8 targets), RadarTracks (20 tracks), BrakeStatus and BrakeCommand held:

- baseline: no history (what the process's own modules and objects cost);
- the history as shipped (message structs, untracked);
- the same payloads decoded into builtins (dicts and lists, tracked): what the same
  history would cost if its objects were tracked.

Prints the tracked-object count and the pause of each.
"""

import argparse
import gc
import statistics
import time
from typing import Any

import msgspec

from aeb_radar_camera.common.messages import BrakeCommand, BrakeStatus, RadarTracks, VerifiedTargets
from aeb_radar_camera.common.messages.codec import decode, encode
from aeb_radar_camera.tools.faults.samples import example


def payloads() -> list[tuple[type[Any], bytes]]:
    """One realistic payload of each kept type."""
    targets = example(VerifiedTargets)
    targets = msgspec.structs.replace(targets, targets=tuple(
        msgspec.structs.replace(targets.targets[0], track_id=i) for i in range(8)))
    tracks = example(RadarTracks)
    tracks = msgspec.structs.replace(tracks, tracks=tuple(
        msgspec.structs.replace(tracks.tracks[0], track_id=i) for i in range(20)))
    return [(VerifiedTargets, encode(targets)), (RadarTracks, encode(tracks)),
            (BrakeStatus, encode(example(BrakeStatus))),
            (BrakeCommand, encode(example(BrakeCommand)))]


def pause(repeat: int) -> tuple[int, float, float]:
    """(tracked objects, median ms, max ms) of a full collection, `repeat` times."""
    gc.collect()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        gc.collect()
        times.append((time.perf_counter() - t0) * 1e3)
    return len(gc.get_objects()), statistics.median(times), max(times)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_gc", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--history", type=int, default=4000, help="messages of each type kept")
    parser.add_argument("--repeat", type=int, default=9, help="collections timed per row")
    args = parser.parse_args(argv)
    rows: list[tuple[str, tuple[int, float, float]]] = [("baseline: no history",
                                                         pause(args.repeat))]
    kept: list[Any] = []
    for tp, payload in payloads():
        kept += [decode(payload, tp) for _ in range(args.history)]
    rows.append(("history: message structs (gc=False)", pause(args.repeat)))
    kept = [msgspec.msgpack.decode(payload) for _, payload in payloads()
            for _ in range(args.history)]
    rows.append(("history: the same as builtins (tracked)", pause(args.repeat)))
    print(f"full garbage collection, {args.history} each of 4 message types kept "
          f"({args.repeat} collections per row)")
    print(f"{'':44s} {'tracked':>9s} {'p50 ms':>8s} {'max ms':>8s}")
    for name, (objects, p50, worst) in rows:
        print(f"{name:44s} {objects:9d} {p50:8.1f} {worst:8.1f}")
    del kept
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
