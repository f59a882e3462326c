"""Pairing radar cycles with actuator lines, pure."""

from aeb_radar_camera.tools.sim.latency import chain_latencies_ns, stage_breakdown_ns

MS = 1_000_000


def test_each_cycle_pairs_with_the_first_line_after_it_within_the_window():
    ends = [0, 75 * MS, 150 * MS, 225 * MS]
    lines = [-10 * MS, 3 * MS, 50 * MS, 79 * MS, 260 * MS, 300 * MS]
    # cycle 0 -> 3 ms; cycle 75 -> 79 (4 ms); cycle 150 -> 260 is too late; 225 -> 260 (35)
    assert chain_latencies_ns(ends, lines, max_ns=20 * MS) == [3 * MS, 4 * MS]
    assert chain_latencies_ns(ends, lines, max_ns=70 * MS) == [3 * MS, 4 * MS, 35 * MS]
    assert chain_latencies_ns([], lines) == [] and chain_latencies_ns(ends, []) == []


def test_stage_breakdown_follows_one_cycle_through_every_stamp():
    ends = {7: 100 * MS, 8: 175 * MS}
    tracks = [(7, 41, 101 * MS, 102 * MS), (8, 42, 176 * MS, 177 * MS), (9, 43, 1, 2)]
    commands = {41: 104 * MS, 42: 180 * MS}
    lines = [50 * MS, 105 * MS, 182 * MS]
    stages = stage_breakdown_ns(ends, tracks, commands, lines)
    assert stages == {"can_link": [1 * MS, 1 * MS], "radar": [1 * MS, 1 * MS],
                      "hop_fusion": [2 * MS, 3 * MS], "hop_brake_serial": [1 * MS, 2 * MS]}
