"""The vehicle gateway's core in this process: what it costs per CAN frame and per
housekeeping tick, on the sample drive (deploy/recordings/vehicle/, SIMULATED).

    python -m benchmarks.bench_vehicle [--repeat N]

Times, per frame, in one run and interleaved (so that machine load hits all alike):

- baseline: cantools' own `decode_message` of the frame (what any DBC decoder costs);
- the core's `on_frame` (look-up, decode, conversion, range checks, the value kept);

and per tick, the core's `poll` (both messages built when due) with the status's
readiness check, as the shell runs them every millisecond while frames flow. Prints
p50 / p99 in microseconds and the frames a second one core could take.
"""

import argparse
import time
from pathlib import Path

import can
import cantools
from can.io.canutils import CanutilsLogReader

from aeb_radar_camera.common.config.loader import load_config
from aeb_radar_camera.common.config.vehicle import VehicleConfig
from aeb_radar_camera.common.messages.radar import BusState
from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.services.vehicle.core import VehicleCore
from aeb_radar_camera.services.vehicle.dbc import load_dbc

LOG = DEPLOY / "recordings" / "vehicle" / "candump-generic-car-drive.log"


def _pct(values: list[int], q: float) -> float:
    v = sorted(values)
    return v[min(len(v) - 1, round(q * (len(v) - 1)))] / 1e3


def frames(path: Path) -> list[can.Message]:
    return list(CanutilsLogReader(str(path)))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_vehicle",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=5, help="passes over the drive")
    args = parser.parse_args(argv)
    gateway = load_config(DEPLOY / "vehicle.toml", VehicleConfig).gateway
    db = load_dbc(gateway.dbc)
    core = VehicleCore(gateway, db)
    log = frames(LOG)
    clock = time.perf_counter_ns
    rows: dict[str, list[int]] = {"baseline: cantools decode_message": [],
                                  "core.on_frame": [], "tick: poll + readiness": []}
    t0 = log[0].timestamp
    for _ in range(args.repeat):
        for msg in log:
            mono = int((msg.timestamp - t0) * 1e9)
            data = bytes(msg.data)
            a = clock()
            try:  # noqa: SIM105 (suppress() would add its own cost to the baseline)
                db.decode_message(msg.arbitration_id, data, decode_choices=False)
            except (KeyError, cantools.database.DecodeError):
                pass
            b = clock()
            core.on_frame(msg.arbitration_id, data, msg.is_extended_id, mono, mono)
            c = clock()
            core.poll(mono, mono)
            core.not_ready_reason(BusState.ACTIVE, mono)
            d = clock()
            rows["baseline: cantools decode_message"].append(b - a)
            rows["core.on_frame"].append(c - b)
            rows["tick: poll + readiness"].append(d - c)
    n = len(log) * args.repeat
    print(f"{n} frames of {LOG.name} ({len(log)} per pass, {args.repeat} passes)")
    print(f"{'per frame / tick':<36} {'p50 us':>8} {'p99 us':>8} {'mean us':>8}")
    for name, times in rows.items():
        print(f"{name:<36} {_pct(times, 0.5):8.2f} {_pct(times, 0.99):8.2f} "
              f"{sum(times) / len(times) / 1e3:8.2f}")
    per_frame = (sum(rows["core.on_frame"]) + sum(rows["tick: poll + readiness"])) / n
    print(f"one core: {1e9 / per_frame:,.0f} frames/s with a tick after every frame "
          f"(the shell ticks at most once a millisecond)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
