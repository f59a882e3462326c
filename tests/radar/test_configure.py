"""The 0x200 configuration write and its confirmation from 0x201 (pure)."""

from aeb_radar_camera.common.config.radar import OutputTypeCfg, RadarWriteSettings
from aeb_radar_camera.services.radar.ars408 import RadarStateFrame, decode_frame
from aeb_radar_camera.services.radar.configure import ConfigWriter, WriteState

S = 1_000_000_000


def state(output_type=1, max_distance=200, quality=1, ext=1, sort=1, rcs=0):
    return RadarStateFrame(1, max_distance, 0, 0, 0, 0, 0, 0, sort, 0, ext, quality,
                           output_type, rcs)


def test_frame_carries_the_requested_fields_under_the_sensor_id():
    w = ConfigWriter(RadarWriteSettings(enabled=True, output_type=OutputTypeCfg.CLUSTERS,
                                        max_distance_m=100, send_quality=False,
                                        sort_index=2, rcs_threshold=1, radar_power=2), 3)
    [frame] = w.start(0)
    assert frame.arb_id == 0x230
    _, sid, r = decode_frame(*frame)
    assert sid == 3 and r.output_type == 2 and r.max_distance_m == 100
    assert r.send_quality == 0 and r.send_ext_info == 1 and r.sort_index == 2
    assert r.rcs_threshold_valid and r.rcs_threshold == 1
    assert r.radar_power_valid and r.radar_power == 2
    assert not r.sensor_id_valid and not r.store_in_nvm


def test_confirmed_by_a_matching_0x201():
    w = ConfigWriter(RadarWriteSettings(enabled=True), 0)
    w.start(0)
    assert w.state is WriteState.WAITING
    assert w.not_ready_reason() == "waiting for 0x201 to confirm the configuration (attempt 1/3)"
    w.on_state(state())
    assert w.state is WriteState.CONFIRMED and w.not_ready_reason() == ""
    assert w.poll(10 * S) == []


def test_resent_when_late_then_failed_with_the_differences():
    w = ConfigWriter(RadarWriteSettings(enabled=True, confirm_timeout_s=1.0, attempts=2), 0)
    assert len(w.start(0)) == 1
    w.on_state(state(output_type=2, max_distance=196))
    assert w.state is WriteState.WAITING          # an old 0x201 may still be in flight
    assert w.poll(S // 2) == []
    assert len(w.poll(S + 1)) == 1                # attempt 2
    assert w.poll(2 * S + 2) == []
    assert w.state is WriteState.FAILED and w.frames_sent == 2
    assert w.not_ready_reason() == ("radar state differs from the configuration written: "
                                    "output_type=clusters (want objects), "
                                    "max_distance_m=196 (want 200)")


def test_a_change_after_confirmation_is_reported():
    w = ConfigWriter(RadarWriteSettings(enabled=True), 0)
    w.start(0)
    w.on_state(state())
    w.on_state(state(quality=0))
    assert w.state is WriteState.FAILED
    assert "send_quality=0 (want 1)" in w.not_ready_reason()


def test_disabled_writes_nothing_and_is_always_ready():
    w = ConfigWriter(RadarWriteSettings(), 0)
    assert w.start(0) == [] and w.poll(100 * S) == []
    w.on_state(state(output_type=2))
    assert w.not_ready_reason() == ""
