"""The latency benchmark's pure parts: following a cycle through the stack's stamps and
the floor relays' stamps into the same seven stages; knowing when a cycle's last frame
is in without decoding it."""

from aeb_radar_camera.services.radar.ars408 import ObjectGeneral, object_cycle_frames
from aeb_radar_camera.tools.sim.can_links import slcan_line
from benchmarks.floor_relay import CycleEnd, command_size, pad, tracks_size
from benchmarks.latency_chain import (
    STAGES,
    BrakeStamp,
    CommandStamp,
    TracksStamp,
    floor_chains,
    line_after,
    stack_chains,
    stages_ns,
    summarize,
    zenoh_ns,
)

US = 1_000


def test_a_stack_cycle_splits_into_seven_stages_that_add_up():
    written = {7: 1000 * US}
    tracks = [TracksStamp(7, 41, 1100 * US, 1400 * US),
              TracksStamp(8, 42, 2000 * US, 2100 * US)]      # never written: left out
    processing = {41: 300 * US, 42: 1}
    commands = {41: CommandStamp(9, 2200 * US)}
    brake = {9: BrakeStamp(2700 * US, 2800 * US)}
    lines = [500 * US, 2900 * US, 80_000 * US]
    chains = stack_chains(written, tracks, processing, commands, brake, lines)
    assert chains == [(1000 * US, 1100 * US, 1400 * US, 1900 * US, 2200 * US, 2700 * US,
                       2800 * US, 2900 * US)]
    st = stages_ns(chains)
    assert [st[s][0] for s in STAGES] == [100 * US, 300 * US, 500 * US, 300 * US, 500 * US,
                                          100 * US, 100 * US]
    assert st["total"] == [1900 * US] == [sum(st[s][0] for s in STAGES)]
    assert zenoh_ns(chains) == [1000 * US]


def test_cycles_missing_a_stamp_or_a_line_in_time_are_left_out():
    written = {1: 0, 2: 75_000 * US, 3: 150_000 * US}
    tracks = [TracksStamp(1, 10, 100, 200), TracksStamp(2, 11, 75_100 * US, 75_200 * US),
              TracksStamp(3, 12, 150_100 * US, 150_200 * US)]
    processing = {10: 50, 11: 50, 12: 50}
    commands = {10: CommandStamp(1, 300), 11: CommandStamp(2, 75_300 * US),
                12: CommandStamp(3, 150_300 * US)}
    brake = {1: BrakeStamp(400, 500), 3: BrakeStamp(150_400 * US, 150_500 * US)}  # 2: none
    lines = [600, 150_400 * US + 25_000 * US]      # cycle 3's line 25 ms late
    assert len(stack_chains(written, tracks, processing, commands, brake, lines)) == 1


def test_a_floor_cycle_pairs_with_its_report_and_the_first_line_after_it():
    written = {5: 1000}
    reports = [(5, 1100, 1150, 1600, 1650, 2100, 2150), (6, 1, 2, 3, 4, 5, 6)]
    chains = floor_chains(written, reports, [900, 2300])
    assert chains == [(1000, 1100, 1150, 1600, 1650, 2100, 2150, 2300)]
    assert zenoh_ns(chains) == [450 + 450]
    assert line_after([10, 20, 30], 20, 5) == 20 and line_after([10, 20], 21, 5) is None


def test_summary_percentiles_in_ms():
    s = summarize([i * 1_000_000 for i in range(1, 101)])
    assert s is not None and s.n == 100 and s.max_ms == 100.0
    assert 50.0 <= s.p50_ms <= 51.0 and 98.0 <= s.p99_ms <= 100.0
    assert summarize([]) is None


def test_cycle_end_counts_the_frames_the_status_frame_announces():
    objects = [ObjectGeneral(i, 5.0 + i, 0.0, -1.0, 0.0, 0, 4.0) for i in range(3)]
    frames = object_cycle_frames(objects, 321)
    lines = [slcan_line(f)[:-1] for f in frames]
    # general frames only in this cycle: one frame per object
    end = CycleEnd(frames_per_object=1)
    done = [end.line(raw) for raw in lines]
    assert done == [False, False, False, True] and end.counter == 321 and end.objects == 3
    empty = slcan_line(object_cycle_frames([], 9)[0])[:-1]
    assert end.line(empty) and end.counter == 9
    assert not end.line(b"t201812345678")      # a frame outside any cycle
    assert not end.line(b"t60A4ZZ")            # a status frame it cannot read


def test_relay_payloads_are_as_large_as_the_messages_they_stand_for():
    assert tracks_size(0) < tracks_size(1) < tracks_size(10)
    assert 100 < command_size() < 400
    assert len(pad(b"abc", 10)) == 10 and pad(b"abcdef", 3) == b"abcdef"


def test_cpu_share_of_a_run_counts_busy_and_stolen_time():
    from benchmarks.bench_latency import cpu_share

    before = [100, 0, 50, 800, 10, 0, 0, 40]
    after = [150, 0, 75, 850, 10, 0, 0, 90]       # +50 user +25 sys +50 idle +50 steal
    assert cpu_share(before, after) == {"busy_pct": 42.9, "steal_pct": 28.6}
    assert cpu_share([], after) == {}
