"""A flood of well-formed radar tracks on radar/<sensor>/tracks (no key needed in the
default profile): fusion decides at most one cycle per `min_cycle_interval_s`, the newest
of each interval, and sheds the rest (`tracks_shed`) instead of signing a command for
every message. The gate on a fake clock, then the fusion service as its own process."""

import itertools
import re
import time
from pathlib import Path

import pytest

from common.clock import wall_ns
from common.keys import FUSION_BRAKE_CMD, RADAR_TRACKS
from services.fusion.shell import RadarGate
from tests.fusion.helpers import CALIBRATION, cycle, track
from tests.support import Collector, HealthWatch, ServiceProcess, open_bus, python_module

MS = 1_000_000


def test_the_gate_lets_one_cycle_per_interval_through_the_newest_winning():
    gate = RadarGate(50 * MS)
    assert gate.offer(cycle(seq=0), 0, 0)                 # the first at once
    for i in range(1, 6):                                 # five more within 10 ms
        assert not gate.offer(cycle(seq=i), i * MS, i * 2 * MS)
    assert gate.shed == 4 and gate.due(49 * MS) is None
    assert gate.wait_ns(20 * MS) == 30 * MS
    ready = gate.due(50 * MS)
    assert ready is not None and ready[0].header.seq == 5
    assert gate.due(60 * MS) is None and not gate.waiting
    assert not gate.offer(cycle(seq=6), 0, 70 * MS)       # slot taken at 50 ms
    assert gate.offer(cycle(seq=7), 0, 200 * MS) is False  # one waits: it goes first
    assert gate.shed == 5


def test_a_radar_at_its_own_rate_is_never_held_back():
    gate = RadarGate(50 * MS)
    assert all(gate.offer(cycle(seq=i), 0, i * 75 * MS) for i in range(100))
    assert gate.shed == 0


@pytest.mark.slow
def test_a_track_flood_gets_one_command_per_cycle_interval(router, tmp_path: Path):
    config = tmp_path / "fusion.toml"
    config.write_text(f'[zenoh]\nconnect = ["{router}"]\n[fusion]\ninstance = "flood"\n'
                      f'calibration = "{CALIBRATION}"\nstats_interval_s = 1.0\n'
                      "min_cycle_interval_s = 0.05\n")
    with open_bus(router) as bus:
        commands = Collector()
        bus.subscribe(FUSION_BRAKE_CMD, commands, instance="flood")
        fusion = ServiceProcess("fusion", python_module("services.fusion", "-c",
                                                        str(config)), tmp_path)
        try:
            HealthWatch(bus).wait_alive("fusion", "flood", 120)
            pub = bus.publisher(RADAR_TRACKS, sensor="front")
            pub.put(cycle(track(), seq=0, stamp_ns=wall_ns()))
            commands.wait_until(lambda m: m.radar_seq == 0, 60)      # fusion is serving
            flood_s, seq = 2.0, 1
            t0 = time.monotonic()
            while time.monotonic() - t0 < flood_s:
                pub.put(cycle(track(), seq=seq, stamp_ns=wall_ns()))
                seq += 1
            elapsed = time.monotonic() - t0
            last = seq - 1
            # the newest of the flood is decided at the end of its interval
            commands.wait_until(lambda m: m.radar_seq == last, 60)
            during = [m for m in commands.messages if 0 < m.radar_seq <= last]
        finally:
            fusion.stop()
    shed = [int(n) for n in re.findall(r"tracks_shed=(\d+)", fusion.log_path.read_text())]
    assert seq > 2000, f"the flood published only {seq} cycles"   # >= 1,000/s
    # one command per 50 ms at most (fusion's clock: Zenoh may still deliver the flood
    # after it ended), processing time aside
    stamps = [m.header.pub_mono_ns for m in during]
    span_s = (stamps[-1] - stamps[0]) / 1e9
    assert len(during) >= 5 and (len(during) - 1) / span_s <= 1 / 0.05 * 1.1, \
        (len(during), span_s, elapsed)
    assert min(b - a for a, b in itertools.pairwise(stamps)) >= 30 * MS
    seqs = [m.header.seq for m in commands.messages]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))       # contiguous commands
    assert shed and shed[-1] >= seq - 1 - len(during) - 5, (shed[-1:], seq, len(during))
