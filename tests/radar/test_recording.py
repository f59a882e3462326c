"""The real ARS408 recording (tests/data/ars408, see its SOURCE.md): every cycle
assembled, counts equal to the status messages', and the scene its recorders describe."""

import statistics
from collections import Counter

import pytest

from aeb_radar_camera.common.messages.radar import BusState
from aeb_radar_camera.services.radar.ars408 import decode_frame
from tests.can_support import RECORDING_CYCLES, RECORDING_FRAMES, recording_messages, run_recording


@pytest.fixture(scope="module")
def recording():
    return run_recording()


def decoded(arb_id):
    return [decode_frame(arb_id, bytes(m.data))[2] for m in recording_messages()
            if m.arbitration_id == arb_id]


def test_every_frame_decodes_and_every_cycle_is_assembled(recording):
    core, results = recording
    assert len(recording_messages()) == RECORDING_FRAMES
    statuses = decoded(0x60A)
    assert len(statuses) == len(results) == RECORDING_CYCLES
    assert [r.meas_counter for r in results] == [s.meas_counter for s in statuses]
    assert [r.n_detections for r in results] == [s.n_objects for s in statuses]
    assert all(r.complete for r in results)
    assert core.rejected.snapshot() == {}
    assert core.cycles_total == RECORDING_CYCLES and core.cycles_incomplete == 0
    assert core.meas_counter_gaps == 0
    assert core.firmware == "4.30.2"
    assert 74.0 < core.cycle_period_ms < 76.0       # SOURCE.md: median 75 ms


def test_radar_state_matches_the_source_description(recording):
    core, _ = recording
    state = core.radar_state
    assert state is not None
    assert state.output_type == 1 and state.send_quality and state.send_ext_info
    assert state.max_distance_m == 200 and state.sensor_id == 0
    assert state.motion_rx_state == 3                # no speed / yaw input: parked
    assert not (state.persistent_error or state.temperature_error or state.voltage_error)
    assert core.not_ready_reason(BusState.ACTIVE, core.last_cycle_mono_ns or 0) == ""


def test_decoded_scene_has_the_car_ahead_and_the_wide_object():
    objects = decoded(0x60B)
    car = [o for o in objects if abs(o.dist_long_m - 11.4) <= 0.2 and abs(o.dist_lat_m) <= 1.0]
    # The car straight ahead at 11.4 m in most cycles, RCS about +26..+30 dBsm, stationary;
    # its reflection point wanders across the car's width (mostly 0.2..0.6 m left).
    assert len(car) > 0.9 * RECORDING_CYCLES
    assert statistics.median(o.dist_lat_m for o in car) == pytest.approx(0.2, abs=0.05)
    assert 26.0 <= statistics.median(o.rcs_dbsm for o in car) <= 30.5
    assert all(o.vrel_long_mps == 0 for o in car)
    # The radar's object ID of that car swaps (32 and 0): IDs are not to be trusted.
    assert {o.id for o in car} == {0, 32}
    wide_ids = {e.id for e in decoded(0x60D) if e.obj_class == 6}
    wide = [o for o in objects if abs(o.dist_long_m - 17.6) <= 0.2 and o.id in wide_ids]
    assert len(wide) > 100
    assert abs(statistics.median(o.dist_lat_m for o in wide)) < 0.5


def test_tracker_holds_one_confirmed_track_on_the_car(recording):
    _, results = recording
    ids: Counter[int] = Counter()
    for r in results[2:]:
        near = [t for t in r.tracks if t.confirmed and abs(t.x_m - 11.4) < 0.3
                and abs(t.y_m) < 2.0]
        assert len(near) == 1
        ids[near[0].track_id] += 1
        assert abs(near[0].range_rate_mps) < 0.2     # parked: not closing
    [(track_id, n)] = ids.items()                    # the same track all along
    assert n == RECORDING_CYCLES - 2
    last = next(t for t in results[-1].tracks if t.track_id == track_id)
    assert last.x_m == pytest.approx(11.4, abs=0.1) and last.y_m == pytest.approx(0.2, abs=0.3)
    assert last.hits == RECORDING_CYCLES and last.obj_class == 1     # car
    assert any(t.confirmed and abs(t.x_m - 17.6) < 0.3 for t in results[-1].tracks)
