"""The latency benchmark runs end to end on a short measurement (figures not asserted:
benchmarks report, tests do not time), and its floor relays forward a cycle."""

import json
import subprocess
import sys

import pytest

from aeb_radar_camera.services.radar.ars408 import ObjectGeneral, object_cycle_frames
from aeb_radar_camera.tools.sim.can_links import SlcanPtyLink
from aeb_radar_camera.tools.sim.pty_pair import PtyPair
from aeb_radar_camera.tools.sim.radar_feed import RadarFeed
from aeb_radar_camera.tools.sim.scenario import RadarLook
from benchmarks import bench_latency
from benchmarks.bench_brake import LineTimes
from benchmarks.floor_relay import FRAMES_PER_OBJECT
from benchmarks.latency_chain import floor_chains
from tests.support import wait_for

pytestmark = pytest.mark.slow


def test_the_floor_relays_carry_a_cycle_from_the_can_pty_to_the_serial_pty(router, tmp_path):
    link, pty = SlcanPtyLink(), PtyPair(tmp_path / "serial")
    base = [sys.executable, "-m", "benchmarks.floor_relay"]
    args = ["--connect", router]
    reports_path = tmp_path / "reports.txt"
    with open(reports_path, "w") as reports_out:
        procs: list[subprocess.Popen[str]] = [
            subprocess.Popen([*base, "serial", *args, "--port", str(pty.path)],
                             stdout=reports_out, text=True),
            subprocess.Popen([*base, "hop", *args], text=True),
            subprocess.Popen([*base, "can", *args, "--channel", link.path], text=True)]

    def reports() -> list[tuple[int, ...]]:
        return bench_latency.read_reports(reports_path.read_text().splitlines())

    lines = LineTimes(pty.master_fd)
    try:
        link.wait_open(60)
        feed = RadarFeed(link, RadarLook())
        written: dict[int, int] = {}
        started: dict[int, int] = {}

        def through() -> bool:     # until the relays' subscriptions have propagated
            counter = len(written)
            status, general = object_cycle_frames(
                [ObjectGeneral(1, 9.0, 0.0, -2.0, 0.0, 0, 5.0)], counter)
            # three frames per object, as the simulated radar sends (the relay counts them)
            frames = [status] + [general] * FRAMES_PER_OBJECT
            started[counter], written[counter] = feed.send_paced(frames)
            return bool(floor_chains(written, reports(), sorted(lines.times)))

        wait_for(through, 60, 0.2, "a cycle through the floor relays")
        chain = floor_chains(written, reports(), sorted(lines.times))[-1]
        counter = next(c for c, t in written.items() if t == chain[0])
        # read, published, received, published, received, written: in order, and after
        # the cycle's first write (the last write is stamped once os.write returned: the
        # relay may have read it before); the line is read after its relay got the
        # payload (maybe before its write stamp)
        assert list(chain[1:7]) == sorted(chain[1:7]) and chain[1] >= started[counter]
        assert chain[7] >= chain[5]
    finally:
        lines.stop()
        for p in procs:
            p.terminate()
            p.wait(10)
        link.close()
        pty.remove()


def test_report_lines_are_read_whole_and_anything_else_is_skipped():
    lines = ["1 2 3 4 5 6 7", "warning: something", "8 9 10 11 12 13", "1 2 3 4 5 6 x",
             "14 15 16 17 18 19 20"]
    assert bench_latency.read_reports(lines) == [(1, 2, 3, 4, 5, 6, 7),
                                                 (14, 15, 16, 17, 18, 19, 20)]


def test_benchmark_runs_and_writes_its_table_plot_and_json(tmp_path, capsys):
    assert bench_latency.main(["--seconds", "4", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "TOTAL: last CAN frame -> brake bytes" in out and "radar-to-brake p99" in out
    assert (tmp_path / "bench_latency.png").stat().st_size > 0
    result = json.loads((tmp_path / "bench_latency.json").read_text())
    assert result["stack"]["total"]["n"] >= 20 and result["floor"]["total"]["n"] >= 20
    assert result["floor_zenoh_2_hops"]["p50_ms"] > 0
