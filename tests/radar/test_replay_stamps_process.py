"""The radar service replaying a candump log with a bad stamp in the middle (`(inf)`, or
a frame stamped 1e6 s ahead) goes on publishing the cycles after it, counts the frame
in its status (`bus:replay_bad_stamp`, `bus:replay_stamp_jump`) and logs it: a paced
replay never stalls without a word."""

import pytest

from aeb_radar_camera.common.keys import RADAR_STATUS, RADAR_TRACKS
from tests.radar.test_replay_corrupt import BAD_STAMPS, first_cycles
from tests.support import Collector, HealthWatch, ServiceProcess, open_bus, python_module, wait_for

pytestmark = pytest.mark.slow

SECONDS = 3.0          # recorded seconds played, the bad frame in the middle
CYCLES = 40            # the recording's cycles in them (one every 75 ms)


@pytest.mark.parametrize("kind,counter", [("infinite", "bus:replay_bad_stamp"),
                                          ("a_million_seconds_ahead",
                                           "bus:replay_stamp_jump")])
def test_a_bad_stamp_is_counted_and_the_replay_goes_on(tmp_path, router, kind, counter):
    log, _ = first_cycles(tmp_path, BAD_STAMPS[kind], SECONDS)
    config = tmp_path / "replay.toml"
    config.write_text(f"""
[zenoh]
connect = ["{router}"]
[radar]
status_period_s = 0.5
[radar.can]
interface = "replay"
[radar.replay]
file = "{log}"
pace = "realtime"
loop = false
exit_at_end = false
[[radar.sensors]]
name = "front"
sensor_id = 0
""")
    with open_bus(router) as bus:
        health = HealthWatch(bus)
        tracks, status = Collector(), Collector()
        bus.subscribe(RADAR_TRACKS, tracks, sensor="front")
        bus.subscribe(RADAR_STATUS, status, sensor="front")
        proc = ServiceProcess("radar-replay", python_module("aeb_radar_camera.services.radar",
                                                            "--config",
                                                            str(config)), tmp_path)
        try:
            health.wait_alive("radar", "front")
            # every cycle after the bad frame too (a few may fall before the subscriber)
            wait_for(lambda: len(tracks.messages) >= CYCLES - 6, 60, interval_s=0.1,
                     what=f"the cycles after the bad frame (got {len(tracks.messages)})")
            got = status.wait_until(lambda s: s.rejected.get(counter, 0) >= 1, 30)
            assert got.rejected.get(counter, 0) >= 1, got.rejected
        finally:
            proc.stop()
        assert f"replay_{counter.split('replay_')[1]}" in proc.log_path.read_text()
