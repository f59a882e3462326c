"""Radar-to-brake latency from the two ends of the chain, pure: the monotonic time each
radar cycle's last CAN frame was written (the simulated radar) and the time each command
line arrived on the actuator's serial line (the simulated actuator), same host.

The brake service writes one line per fusion command (one per radar cycle) and, between
commands, a heartbeat line at most every `heartbeat` period (50 ms by default, shorter
than the 72-76 ms radar cycle). The heartbeat after a command comes a heartbeat period
after it, so the first line after a cycle's last frame is that cycle's command line as
long as the chain is faster than the radar period minus the heartbeat period (about
20 ms); `max_ns` keeps a line that came later than that out of the figures.
"""

import bisect
from collections.abc import Sequence

DEFAULT_MAX_NS = 20_000_000


def chain_latencies_ns(cycle_ends_ns: Sequence[int], line_times_ns: Sequence[int],
                       max_ns: int = DEFAULT_MAX_NS) -> list[int]:
    """For each cycle end, the delay to the first line after it (within `max_ns`).

    Both sequences must be in increasing order. Cycles with no line in time are left out
    (count them as len(cycle_ends) - len(result)).
    """
    out: list[int] = []
    j = 0
    for end in cycle_ends_ns:
        while j < len(line_times_ns) and line_times_ns[j] <= end:
            j += 1
        if j < len(line_times_ns) and line_times_ns[j] - end <= max_ns:
            out.append(line_times_ns[j] - end)
    return out


STAGES = ("can_link", "radar", "hop_fusion", "hop_brake_serial")


def stage_breakdown_ns(
    cycle_ends_ns: dict[int, int],
    tracks: Sequence[tuple[int, int, int, int]],
    commands: dict[int, int],
    line_times_ns: Sequence[int],
    max_ns: int = DEFAULT_MAX_NS,
) -> dict[str, list[int]]:
    """The chain per stage, from the stamps the messages carry (same host):

    - can_link: the simulated radar wrote the cycle's last frame -> the radar service
      received it (`RadarTracks.last_frame_mono_ns`);
    - radar: -> RadarTracks published (decode, prefilter, merge, track);
    - hop_fusion: -> BrakeCommand published (Zenoh hop, align, verify, decide);
    - hop_brake_serial: -> the command line arrived on the actuator (Zenoh hop,
      validation, serial write, the pty).

    `cycle_ends_ns`: meas_counter -> last frame written; `tracks`: (meas_counter,
    radar seq, last_frame_mono_ns, pub_mono_ns) per RadarTracks; `commands`: radar seq ->
    BrakeCommand pub_mono_ns; `line_times_ns` increasing. Cycles missing anywhere, or
    whose line came later than `max_ns` after the command, are left out.
    """
    out: dict[str, list[int]] = {s: [] for s in STAGES}
    for counter, seq, last_frame, published in tracks:
        written = cycle_ends_ns.get(counter)
        cmd = commands.get(seq)
        if written is None or cmd is None:
            continue
        i = bisect.bisect_right(line_times_ns, cmd)
        if i >= len(line_times_ns) or line_times_ns[i] - cmd > max_ns:
            continue
        for stage, value in zip(STAGES, (last_frame - written, published - last_frame,
                                         cmd - published, line_times_ns[i] - cmd),
                                strict=True):
            out[stage].append(value)
    return out
