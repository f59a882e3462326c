"""The brake's command validation in this process: what authentication adds per command.

    python -m benchmarks.bench_brake_validate [--count N]

Times, per command, in one run and interleaved (so that machine load hits all alike):

- baseline: decoding the payload (`common.messages.decode`), which validation always did;
- the MAC check alone (`common.command_auth.mac_problem`);
- the whole check (`CommandValidator.check`: instance, decode, MAC, fields, age,
  session, sequence) on a fresh, signed, in-sequence command.

Prints p50 / p99 in microseconds.
"""

import argparse
import time

from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.command_auth import CommandSigner, mac_problem, new_key
from aeb_radar_camera.common.config.brake import AgeClock
from aeb_radar_camera.common.keys import FUSION_BRAKE_CMD
from aeb_radar_camera.common.messages import BrakeCommand, Decision, Header, VerifierStatus, decode
from aeb_radar_camera.services.brake.commands import Accepted, CommandValidator

PERIOD_NS = 20_000_000


def _payloads(signer: CommandSigner, count: int, t0: int, w0: int) -> list[bytes]:
    return [signer.sign(BrakeCommand(
        header=Header(seq=i, source="fusion/primary", stamp_ns=w0 + i * PERIOD_NS,
                      pub_mono_ns=t0 + i * PERIOD_NS),
        instance="primary", decision=Decision.NONE, brake_level_pct=0.0,
        verifier_status=VerifierStatus.OK, held=False, track_id=-1, range_m=None, ttc_s=None,
        reason="bench", radar_seq=i, radar_last_frame_mono_ns=t0 + i * PERIOD_NS))
        for i in range(count)]


def _pct(values: list[int], q: float) -> float:
    v = sorted(values)
    return v[min(len(v) - 1, round(q * (len(v) - 1)))] / 1e3


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_brake_validate",
                                     description=__doc__)
    parser.add_argument("--count", type=int, default=20000)
    args = parser.parse_args(argv)
    key = new_key("primary")
    keys = {key.key_id: key}
    expected = FUSION_BRAKE_CMD.key("ego", instance="primary")
    validator = CommandValidator(expected, "primary", AgeClock.MONOTONIC, 100_000_000,
                                 5_000_000, keys)
    t0, w0 = mono_ns(), wall_ns()
    payloads = _payloads(CommandSigner(key), args.count, t0, w0)
    rows: dict[str, list[int]] = {"baseline: decode": [], "MAC check": [],
                                  "validate (whole check)": []}
    clock = time.perf_counter_ns
    for i, payload in enumerate(payloads):
        rx = t0 + i * PERIOD_NS + 1_000_000
        a = clock()
        cmd = decode(payload, BrakeCommand)
        b = clock()
        problem = mac_problem(payload, cmd, keys)
        c = clock()
        result = validator.check(payload, expected, rx, w0 + (rx - t0), True)
        d = clock()
        if problem is not None or not isinstance(result, Accepted):
            raise RuntimeError(f"command {i} refused: {problem or result}")
        rows["baseline: decode"].append(b - a)
        rows["MAC check"].append(c - b)
        rows["validate (whole check)"].append(d - c)
    print(f"brake command validation, {args.count} signed commands of {len(payloads[0])} B; us")
    print(f"{'path':<28}{'p50':>8}{'p99':>8}")
    for name, values in rows.items():
        print(f"{name:<28}{_pct(values, 0.5):>8.2f}{_pct(values, 0.99):>8.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
