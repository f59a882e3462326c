"""The radar service as its own process, fed the real recording in real time through a
python-can interface that crosses processes, with Zenoh subscribers in the test.

Always: slcan over a pseudo-terminal (the test plays the USB-CAN adapter with the radar
behind it). Also: vcan, when this kernel can create one (skipped with the kernel's
reason otherwise).
"""

import signal
import threading
from collections.abc import Callable
from pathlib import Path

import can
import pytest

from aeb_radar_camera.common.keys import RADAR_STATUS, RADAR_TRACKS
from aeb_radar_camera.common.messages import RadarTracks, decode
from aeb_radar_camera.services.radar.ars408 import decode_frame
from aeb_radar_camera.tools.sim.can_links import SlcanPtyLink, replay_log
from aeb_radar_camera.tools.sim.radar_feed import PythonCanSink
from tests.can_support import RECORDING, VcanUnavailable, vcan_interface
from tests.support import Collector, HealthWatch, ServiceProcess, open_bus, python_module, wait_for

pytestmark = pytest.mark.slow

REPLAY_S = 4.0     # recorded seconds fed in real time: 53 cycles, four 0x201 / 0x700


def write_config(path: Path, router: str, can_table: str) -> Path:
    path.write_text(f"""
vehicle = "ego"
[zenoh]
connect = ["{router}"]
[radar]
status_period_s = 0.5
{can_table}
[[radar.sensors]]
name = "front"
sensor_id = 0
[radar.sensors.configure]
enabled = true          # the recording's own 0x201 confirms these values
output_type = "objects"
max_distance_m = 200
""")
    return path


class Received:
    """Tracks with their receive time on this host's monotonic clock, and status."""

    def __init__(self, bus) -> None:
        self.tracks: list[tuple[RadarTracks, int]] = []
        self.status = Collector()
        self._lock = threading.Lock()
        bus.subscribe_raw(RADAR_TRACKS, self._on_tracks, sensor="front")
        bus.subscribe(RADAR_STATUS, self.status, sensor="front")

    def _on_tracks(self, payload: bytes, key: str, mono: int) -> None:
        with self._lock:
            self.tracks.append((decode(payload, RadarTracks), mono))

    def snapshot(self) -> list[tuple[RadarTracks, int]]:
        with self._lock:
            return list(self.tracks)


def run_against_the_service(
    tmp_path: Path, router: str, can_table: str, feed: Callable[[threading.Event], None],
) -> tuple[list[tuple[RadarTracks, int]], Collector, ServiceProcess]:
    config = write_config(tmp_path / "radar.toml", router, can_table)
    with open_bus(router, source="test") as bus:
        health = HealthWatch(bus)
        got = Received(bus)
        proc = ServiceProcess("radar", python_module("aeb_radar_camera.services.radar", "--config",
                                                     str(config)),
                              tmp_path)
        stop = threading.Event()
        feeder = threading.Thread(target=feed, args=(stop,), daemon=True)
        try:
            health.wait_alive("radar", "front")
            feeder.start()
            wait_for(lambda: len(got.snapshot()) >= 40, 60, 0.05, "40 cycles of tracks")
            got.status.wait_until(lambda s: s.ready and s.firmware == "4.30.2", 30)
        finally:
            stop.set()
            feeder.join(10)
            code = proc.stop()
        assert code == 0, proc.output()
        wait_for(lambda: not health.is_alive("radar", "front"), 30, what="token gone")
        return got.snapshot(), got.status, proc


def check(tracks: list[tuple[RadarTracks, int]], status: Collector, interface: str) -> None:
    msgs = [m for m, _ in tracks]
    assert [m.header.seq for m in msgs] == list(range(msgs[0].header.seq,
                                                      msgs[0].header.seq + len(msgs)))
    assert all(m.complete and m.sensor == "front" for m in msgs[1:])
    car = [t for t in msgs[-1].tracks if t.confirmed and abs(t.x_m - 11.4) < 0.3]
    assert len(car) == 1 and abs(car[0].range_rate_mps) < 0.2
    # Same host: the last CAN frame's receive time precedes our receipt, by little.
    latencies = [(mono - m.last_frame_mono_ns) / 1e6 for m, mono in tracks]
    assert all(0 < lat < 1000 for lat in latencies), latencies
    last = status.messages[-1]
    assert last.interface == interface and last.cycle_period_ms == pytest.approx(75, abs=2)
    assert last.frames_per_s > 100 and last.cycles_incomplete <= 1
    assert last.radar_state is not None and last.radar_state.output_type == 1


def test_service_process_over_slcan_pty(tmp_path, router):
    with SlcanPtyLink() as link:
        def feed(stop: threading.Event) -> None:
            link.wait_open(30)
            replay_log(str(RECORDING), link.send, pace="realtime", stop=stop,
                       max_duration_s=REPLAY_S)

        can_table = f"""[radar.can]
interface = "slcan"
channel = "{link.path}"
options = {{ sleep_after_open = 0 }}"""
        tracks, status, _ = run_against_the_service(tmp_path, router, can_table, feed)
        check(tracks, status, "slcan")
        # The service wrote the configuration across the process boundary.
        cfg = link.wait_frame(lambda f: f.arb_id == 0x200, 5)
        assert decode_frame(*cfg)[2].output_type == 1
        assert link.commands[:2] == ["C", "S6"] and "O" in link.commands


@pytest.fixture
def vcan_name():
    """A vcan interface, or a skip with the kernel's reason (before the router starts)."""
    try:
        with vcan_interface() as name:
            yield name
    except VcanUnavailable as exc:
        pytest.skip(f"no vcan in this kernel ({exc}); the slcan-pty variant covers the path")


def test_service_process_over_vcan(vcan_name, tmp_path, router):
    with can.Bus(interface="socketcan", channel=vcan_name) as sender:
        def feed(stop: threading.Event) -> None:
            replay_log(str(RECORDING), PythonCanSink(sender).send, pace="realtime", stop=stop,
                       max_duration_s=REPLAY_S)

        can_table = f"""[radar.can]
interface = "socketcan"
channel = "{vcan_name}"
"""
        tracks, status, _ = run_against_the_service(tmp_path, router, can_table, feed)
        check(tracks, status, "socketcan")


def test_invalid_configuration_exits_2_naming_the_field(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[radar.tracker]\nconfirm_hits = 0\n")
    proc = ServiceProcess("radar-bad", python_module("aeb_radar_camera.services.radar", "--config",
                                                     str(bad)),
                          tmp_path)
    assert proc.proc.wait(60) == 2
    assert "radar.tracker.confirm_hits" in proc.output()
    proc.stop()
    missing = tmp_path / "missing.toml"
    missing.write_text('[radar.can]\ninterface = "replay"\n[radar.replay]\nfile = "/nope.log"\n')
    proc = ServiceProcess("radar-missing",
                          python_module("aeb_radar_camera.services.radar", "--config",
                                        str(missing)), tmp_path)
    assert proc.proc.wait(60) == 2
    assert "/nope.log" in proc.output()
    proc.stop()


def test_sigterm_is_a_clean_stop(tmp_path, router):
    config = tmp_path / "replay.toml"
    config.write_text(f"""
[zenoh]
connect = ["{router}"]
[radar.can]
interface = "replay"
[radar.replay]
file = "{RECORDING}"
loop = true
""")
    with open_bus(router) as bus:
        health = HealthWatch(bus)
        tracks = Collector()
        bus.subscribe(RADAR_TRACKS, tracks, sensor="front")
        proc = ServiceProcess("radar-replay", python_module("aeb_radar_camera.services.radar",
                                                            "--config",
                                                            str(config)), tmp_path)
        try:
            health.wait_alive("radar", "front")
            tracks.wait_count(3, 30)
            proc.signal(signal.SIGTERM)
            assert proc.proc.wait(30) == 0
        finally:
            proc.stop()
        assert "radar_stopped" in proc.log_path.read_text()
