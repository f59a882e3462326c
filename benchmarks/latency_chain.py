"""Radar-to-brake latency per stage, pure: each radar cycle followed through the stamps
its messages carry (same host, one monotonic clock), for the stack and for its floor
(benchmarks/floor_relay.py), so that both split into the same seven stages.

A chain is eight monotonic times; the stages are their differences:

| stage | stack | floor |
|---|---|---|
| can_in | last frame written -> radar received it | -> `can` relay read it |
| decode_track | -> RadarTracks published | -> payload published |
| hop_radar_fusion | -> fusion's callback (see below) | -> `hop` relay's callback |
| verify_decide | -> BrakeCommand published | -> payload published |
| hop_fusion_brake | -> the brake's callback | -> `serial` relay's callback |
| brake_write | -> line written to the serial port | -> line written |
| serial_out | -> line read by the actuator | -> line read by the benchmark |

Fusion's receipt is its BrakeCommand's publish time minus `VerifiedTargets.processing_ns`
(receipt to decided, measured by fusion, ending at the command's `pub_mono_ns`): the put
of each message is counted in the hop that follows, for the stack and the floor alike.
"""

import bisect
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

STAGES = ("can_in", "decode_track", "hop_radar_fusion", "verify_decide",
          "hop_fusion_brake", "brake_write", "serial_out")
STAGE_TITLES = {
    "can_in": "CAN in (slcan pty)",
    "decode_track": "decode + track",
    "hop_radar_fusion": "Zenoh hop radar -> fusion",
    "verify_decide": "verify + decide",
    "hop_fusion_brake": "Zenoh hop fusion -> brake",
    "brake_write": "brake: validate + write",
    "serial_out": "serial out (pty)",
}
ZENOH_HOPS = ("hop_radar_fusion", "hop_fusion_brake")
# A line later than this after the receipt that should have caused it is not its line.
DEFAULT_MAX_NS = 20_000_000

Chain = tuple[int, int, int, int, int, int, int, int]


@dataclass(frozen=True)
class TracksStamp:
    meas_counter: int
    radar_seq: int
    last_frame_mono_ns: int
    pub_mono_ns: int


@dataclass(frozen=True)
class CommandStamp:
    cmd_seq: int
    pub_mono_ns: int


@dataclass(frozen=True)
class BrakeStamp:
    rx_mono_ns: int
    written_mono_ns: int


def line_after(lines_ns: Sequence[int], t_ns: int, max_ns: int) -> int | None:
    """The first line read at or after `t_ns`, if within `max_ns` (`lines_ns` sorted)."""
    i = bisect.bisect_left(lines_ns, t_ns)
    if i < len(lines_ns) and lines_ns[i] - t_ns <= max_ns:
        return lines_ns[i]
    return None


def stack_chains(
    written: dict[int, int],
    tracks: Iterable[TracksStamp],
    processing_ns: dict[int, int],
    commands: dict[int, CommandStamp],
    brake: dict[int, BrakeStamp],
    lines_ns: Sequence[int],
    max_ns: int = DEFAULT_MAX_NS,
) -> list[Chain]:
    """One chain per radar cycle seen at every stage.

    `written`: meas_counter -> last frame written; `processing_ns`: radar seq ->
    VerifiedTargets.processing_ns; `commands`: radar seq -> the BrakeCommand; `brake`:
    command seq -> receipt and write (BrakeStatus.last_cmd_rx_mono_ns and
    cmd_to_serial_us); `lines_ns`: the actuator's line read times, sorted. Cycles missing
    anywhere are left out.
    """
    out: list[Chain] = []
    for t in tracks:
        end = written.get(t.meas_counter)
        proc = processing_ns.get(t.radar_seq)
        cmd = commands.get(t.radar_seq)
        if end is None or proc is None or cmd is None:
            continue
        b = brake.get(cmd.cmd_seq)
        if b is None:
            continue
        line = line_after(lines_ns, b.rx_mono_ns, max_ns)
        if line is None:
            continue
        out.append((end, t.last_frame_mono_ns, t.pub_mono_ns, cmd.pub_mono_ns - proc,
                    cmd.pub_mono_ns, b.rx_mono_ns, b.written_mono_ns, line))
    return out


def floor_chains(written: dict[int, int], reports: Iterable[Sequence[int]],
                 lines_ns: Sequence[int], max_ns: int = DEFAULT_MAX_NS) -> list[Chain]:
    """One chain per floor cycle: `reports` are the `serial` relay's lines
    (counter, can_rx, can_pub, hop_rx, hop_pub, serial_rx, serial_written)."""
    out: list[Chain] = []
    for r in reports:
        counter, can_rx, can_pub, hop_rx, hop_pub, ser_rx, ser_written = r
        end = written.get(counter)
        if end is None:
            continue
        line = line_after(lines_ns, ser_rx, max_ns)
        if line is None:
            continue
        out.append((end, can_rx, can_pub, hop_rx, hop_pub, ser_rx, ser_written, line))
    return out


def stages_ns(chains: Sequence[Chain]) -> dict[str, list[int]]:
    """Per stage, the values over every chain; `total` is the whole chain."""
    out: dict[str, list[int]] = {s: [] for s in (*STAGES, "total")}
    for c in chains:
        for i, name in enumerate(STAGES):
            out[name].append(c[i + 1] - c[i])
        out["total"].append(c[-1] - c[0])
    return out


def zenoh_ns(chains: Sequence[Chain]) -> list[int]:
    """The two Zenoh hops of each chain, summed."""
    return [(c[3] - c[2]) + (c[5] - c[4]) for c in chains]


@dataclass(frozen=True)
class Summary:
    n: int
    p50_ms: float
    p95_ms: float
    p99_ms: float
    max_ms: float
    mean_ms: float

    def as_dict(self) -> dict[str, float]:
        return {"n": self.n, "p50_ms": self.p50_ms, "p95_ms": self.p95_ms,
                "p99_ms": self.p99_ms, "max_ms": self.max_ms, "mean_ms": self.mean_ms}


def summarize(values_ns: Sequence[int]) -> Summary | None:
    """Percentiles in ms (numpy's linear interpolation); None when empty."""
    if not values_ns:
        return None
    ms = np.asarray(values_ns, dtype=float) / 1e6
    p50, p95, p99 = (float(np.percentile(ms, q)) for q in (50, 95, 99))
    return Summary(len(ms), round(p50, 4), round(p95, 4), round(p99, 4),
                   round(float(ms.max()), 4), round(float(ms.mean()), 4))
