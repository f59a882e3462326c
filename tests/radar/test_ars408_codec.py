"""The ARS408 table decoder and encoder against ARS408.md.

SPEC below is ARS408.md's byte/bit expressions transcribed by hand, independently of the
table (which places signals by MSB position): every signal of every message is checked
on random payloads, then on hand-built frames with known physical values.
"""

import math

import numpy as np
import pytest

from aeb_radar_camera.services.radar.ars408 import (
    MESSAGES,
    ClusterGeneral,
    ClusterListStatus,
    ClusterQuality,
    EncodeError,
    Kind,
    ObjectExtended,
    ObjectGeneral,
    ObjectListStatus,
    ObjectQuality,
    RadarConfigFrame,
    RadarFrame,
    RadarFrameError,
    RadarStateFrame,
    SpeedInformation,
    Version,
    YawRateInformation,
    arbitration_id,
    classify,
    cluster_cycle_frames,
    decode,
    decode_columns,
    decode_frame,
    ego_motion_frames,
    encode,
    object_cycle_frames,
)
from aeb_radar_camera.services.radar.ars408.dbc import DBC_PATH, render
from aeb_radar_camera.services.radar.ars408.table import BY_KIND

OBJECT_GENERAL = {
    "id": lambda b: b[0],
    "dist_long_m": lambda b: (b[1] << 5 | b[2] >> 3) * 0.2 - 500,
    "dist_lat_m": lambda b: ((b[2] & 7) << 8 | b[3]) * 0.2 - 204.6,
    "vrel_long_mps": lambda b: (b[4] << 2 | b[5] >> 6) * 0.25 - 128,
    "vrel_lat_mps": lambda b: ((b[5] & 0x3F) << 3 | b[6] >> 5) * 0.25 - 64,
    "dyn_prop": lambda b: b[6] & 7,
    "rcs_dbsm": lambda b: b[7] * 0.5 - 64,
}

QUALITY_RMS = {
        "id": lambda b: b[0],
        "dist_long_rms": lambda b: b[1] >> 3,
        "dist_lat_rms": lambda b: (b[1] & 7) << 2 | b[2] >> 6,
        "vrel_long_rms": lambda b: (b[2] >> 1) & 0x1F,
        "vrel_lat_rms": lambda b: (b[2] & 1) << 4 | b[3] >> 4,
}

SPEC = {
    "Obj_0_Status": {
        "n_objects": lambda b: b[0],
        "meas_counter": lambda b: b[1] << 8 | b[2],
        "interface_version": lambda b: b[3] >> 4,
    },
    "Obj_1_General": OBJECT_GENERAL,
    "Obj_2_Quality": {
        **QUALITY_RMS,
        "meas_state": lambda b: (b[6] >> 2) & 7,
        "prob_of_exist": lambda b: b[6] >> 5,
    },
    "Obj_3_Extended": {
        "id": lambda b: b[0],
        "arel_long_mps2": lambda b: (b[1] << 3 | b[2] >> 5) * 0.01 - 10,
        "arel_lat_mps2": lambda b: ((b[2] & 0x1F) << 4 | b[3] >> 4) * 0.01 - 2.5,
        "obj_class": lambda b: b[3] & 7,
        "orientation_deg": lambda b: (b[4] << 2 | b[5] >> 6) * 0.4 - 180,
        "length_m": lambda b: b[6] * 0.2,
        "width_m": lambda b: b[7] * 0.2,
    },
    "Cluster_0_Status": {
        "n_near": lambda b: b[0],
        "n_far": lambda b: b[1],
        "meas_counter": lambda b: b[2] << 8 | b[3],
        "interface_version": lambda b: b[4] >> 4,
    },
    "Cluster_1_General": {
        # As 0x60B except DistLat: 10 bits, offset -102.3.
        **OBJECT_GENERAL,
        "dist_lat_m": lambda b: ((b[2] & 3) << 8 | b[3]) * 0.2 - 102.3,
    },
    "Cluster_2_Quality": {
        # The deviations as 0x60C's.
        **QUALITY_RMS,
        "pdh0": lambda b: b[3] & 7,
        "ambig_state": lambda b: b[4] & 7,
        "invalid_state": lambda b: b[4] >> 3,
    },
    "RadarState": {
        "nvm_read_ok": lambda b: (b[0] >> 6) & 1,
        "max_distance_m": lambda b: (b[1] << 2 | b[2] >> 6) * 2,
        "persistent_error": lambda b: (b[2] >> 5) & 1,
        "interference": lambda b: (b[2] >> 4) & 1,
        "temperature_error": lambda b: (b[2] >> 3) & 1,
        "temporary_error": lambda b: (b[2] >> 2) & 1,
        "voltage_error": lambda b: (b[2] >> 1) & 1,
        "sensor_id": lambda b: b[4] & 7,
        "sort_index": lambda b: (b[4] >> 4) & 7,
        "motion_rx_state": lambda b: b[5] >> 6,
        "send_ext_info": lambda b: (b[5] >> 5) & 1,
        "send_quality": lambda b: (b[5] >> 4) & 1,
        "output_type": lambda b: (b[5] >> 2) & 3,
        "rcs_threshold": lambda b: (b[7] >> 2) & 7,
    },
    "VersionID": {
        "major": lambda b: b[0],
        "minor": lambda b: b[1],
        "patch": lambda b: b[2],
    },
    "RadarCfg": {
        "max_distance_valid": lambda b: b[0] & 1,
        "sensor_id_valid": lambda b: (b[0] >> 1) & 1,
        "radar_power_valid": lambda b: (b[0] >> 2) & 1,
        "output_type_valid": lambda b: (b[0] >> 3) & 1,
        "send_quality_valid": lambda b: (b[0] >> 4) & 1,
        "send_ext_info_valid": lambda b: (b[0] >> 5) & 1,
        "sort_index_valid": lambda b: (b[0] >> 6) & 1,
        "store_in_nvm_valid": lambda b: b[0] >> 7,
        "max_distance_m": lambda b: (b[1] << 2 | b[2] >> 6) * 2,
        "sensor_id": lambda b: b[4] & 7,
        "output_type": lambda b: (b[4] >> 3) & 3,
        "radar_power": lambda b: b[4] >> 5,
        "ctrl_relay_valid": lambda b: b[5] & 1,
        "ctrl_relay": lambda b: (b[5] >> 1) & 1,
        "send_quality": lambda b: (b[5] >> 2) & 1,
        "send_ext_info": lambda b: (b[5] >> 3) & 1,
        "sort_index": lambda b: (b[5] >> 4) & 7,
        "store_in_nvm": lambda b: b[5] >> 7,
        "rcs_threshold_valid": lambda b: b[6] & 1,
        "rcs_threshold": lambda b: (b[6] >> 1) & 7,
    },
    "SpeedInformation": {
        "direction": lambda b: b[0] >> 6,
        "speed_mps": lambda b: ((b[0] & 0x1F) << 8 | b[1]) * 0.02,
    },
    "YawRateInformation": {
        "yaw_rate_dps": lambda b: (b[0] << 8 | b[1]) * 0.01 - 327.68,
    },
}


def test_spec_transcription_covers_every_signal_of_the_table():
    assert set(SPEC) == {m.dbc_name for m in MESSAGES}
    for m in MESSAGES:
        assert set(SPEC[m.dbc_name]) == set(m.record._fields), m.dbc_name


@pytest.mark.parametrize("spec", MESSAGES, ids=lambda m: m.dbc_name)
def test_every_signal_matches_the_spec_on_random_payloads(spec):
    rng = np.random.default_rng(spec.base_id)
    payloads = [bytes(rng.integers(0, 256, spec.dlc, dtype=np.uint8)) for _ in range(300)]
    # Edge patterns: all bits clear, all bits set, alternating.
    payloads += [bytes(spec.dlc), b"\xff" * spec.dlc, b"\xaa" * spec.dlc, b"\x55" * spec.dlc]
    cols = decode_columns(spec, payloads)
    for attr, expr in SPEC[spec.dbc_name].items():
        expected = [expr(p) for p in payloads]
        assert np.allclose(cols.values[attr], expected, atol=1e-9), f"{spec.dbc_name}.{attr}"
    # The scalar decoder agrees with the vectorised one on every valid frame.
    for p, ok in zip(payloads, cols.valid, strict=True):
        if ok:
            record = decode(spec, p)
            for attr, expr in SPEC[spec.dbc_name].items():
                assert getattr(record, attr) == pytest.approx(expr(p), abs=1e-9)
        else:
            with pytest.raises(RadarFrameError) as err:
                decode(spec, p)
            assert err.value.reason == "out_of_range"


def test_hand_built_frames_from_the_recording():
    # The car ahead: ID 32, 11.4 m forward, 0.2 m left, stationary, RCS 26 dBsm.
    spec, sensor, obj = decode_frame(0x60B, bytes.fromhex("204FEC00802001B4"))
    assert (spec.kind, sensor) == (Kind.OBJECT_GENERAL, 0)
    assert obj.id == 32 and obj.dyn_prop == 1
    assert obj.dist_long_m == pytest.approx(11.4) and obj.dist_lat_m == pytest.approx(0.2)
    assert obj.vrel_long_mps == 0 and obj.vrel_lat_mps == 0 and obj.rcs_dbsm == 26.0
    # Left positive: raw 1021 is 0.4 m to the right.
    _, _, wide = decode_frame(0x60B, bytes.fromhex("0050E3FD802001B7"))
    assert wide.dist_long_m == pytest.approx(17.6) and wide.dist_lat_m == pytest.approx(-0.4)
    _, _, status = decode_frame(0x60A, bytes.fromhex("03FBF710"))
    assert status == ObjectListStatus(3, 0xFBF7, 1)
    _, _, q = decode_frame(0x60C, bytes.fromhex("3884A33A0220E8"))
    assert q == ObjectQuality(56, 16, 18, 17, 19, 2, 7)
    _, _, ext = decode_frame(0x60D, bytes.fromhex("007D0FA67080190B"))
    assert ext.obj_class == 6 and ext.length_m == pytest.approx(5.0)
    assert ext.width_m == pytest.approx(2.2) and ext.orientation_deg == pytest.approx(0.0)
    _, _, state = decode_frame(0x201, bytes.fromhex("4019000010F40000"))
    assert state == RadarStateFrame(1, 200, 0, 0, 0, 0, 0, 0, 1, 3, 1, 1, 1, 0)
    _, _, version = decode_frame(0x700, bytes.fromhex("041E0200"))
    assert version == Version(4, 30, 2)


def test_hand_built_cluster_frames():
    # DistLong raw 2560 -> 12.0 m; DistLat raw 0x1FF = 511 -> -0.1 m; VrelLong raw 500
    # -> -3.0 m/s; VrelLat raw 256 -> 0; DynProp 2 (oncoming); RCS raw 100 -> -14 dBsm.
    data = bytes([7, 2560 >> 5, (2560 & 0x1F) << 3 | 0x1, 0xFF, 500 >> 2,
                  (500 & 3) << 6 | 256 >> 3, (256 & 7) << 5 | 2, 100])
    _, sensor, c = decode_frame(0x701 + 0x10 * 3, data)
    assert sensor == 3
    assert c == pytest.approx(ClusterGeneral(7, 12.0, -0.1, -3.0, 0.0, 2, -14.0))
    _, _, q = decode_frame(0x702, bytes([7, 0x84, 0xA3, 0x35, (6 << 3) | 3]))
    assert (q.pdh0, q.ambig_state, q.invalid_state) == (5, 3, 6)
    _, _, s = decode_frame(0x600, bytes([12, 30, 0x01, 0x02, 0x10]))
    assert s == ClusterListStatus(12, 30, 0x0102, 1)


@pytest.mark.parametrize("sensor_id", range(8))
def test_sensor_id_offsets_for_every_message(sensor_id):
    for spec in MESSAGES:
        arb = spec.base_id + 0x10 * sensor_id
        assert arbitration_id(spec.kind, sensor_id) == arb
        assert classify(arb) == (spec, sensor_id)
    frame = encode(ObjectGeneral(5, 10.0, -1.0, -2.5, 0.25, 0, 3.5), sensor_id)
    assert frame.arb_id == 0x60B + 0x10 * sensor_id
    spec, sid, obj = decode_frame(*frame)
    assert (spec.kind, sid) == (Kind.OBJECT_GENERAL, sensor_id)
    assert obj.dist_long_m == pytest.approx(10.0) and obj.dist_lat_m == pytest.approx(-1.0)


def test_sensor_id_outside_0_7_is_refused():
    with pytest.raises(ValueError):
        arbitration_id(Kind.OBJECT_GENERAL, 8)
    with pytest.raises(ValueError):
        encode(Version(1, 2, 3), 8)
    assert classify(0x60B + 0x80) is None


RECORDS = [
    ObjectListStatus(17, 65535, 1),
    ObjectGeneral(255, 249.8, -99.8, -127.75, 63.75, 7, 63.5),
    ObjectGeneral(0, -10.0, 100.0, 127.75, -64.0, 0, -64.0),
    ObjectQuality(9, 0, 31, 15, 16, 5, 7),
    ObjectExtended(3, -10.0, 2.61, 6, 179.6, 51.0, 0.2),
    ClusterListStatus(200, 55, 12345, 2),
    ClusterGeneral(42, 0.2, -99.9, -5.25, 1.5, 3, -20.0),
    ClusterQuality(42, 1, 2, 3, 4, 7, 4, 17),
    RadarStateFrame(1, 200, 1, 0, 1, 0, 1, 5, 2, 3, 1, 0, 2, 1),
    Version(4, 30, 2),
    RadarConfigFrame(max_distance_valid=1, output_type_valid=1, max_distance_m=196,
                     output_type=2, radar_power=3, send_quality=1, sort_index=2,
                     rcs_threshold_valid=1, rcs_threshold=1, store_in_nvm=1, sensor_id=6),
    SpeedInformation(2, 163.82),
    YawRateInformation(-327.68),
    YawRateInformation(327.67),
]


@pytest.mark.parametrize("record", RECORDS, ids=lambda r: type(r).__name__)
def test_encode_decode_round_trip(record):
    frame = encode(record, sensor_id=2)
    spec, sid, back = decode_frame(*frame)
    assert sid == 2 and type(back) is type(record) and len(frame.data) == spec.dlc
    for a, b in zip(back, record, strict=True):
        assert a == pytest.approx(b, abs=1e-9)


def test_round_trip_on_random_physical_values():
    rng = np.random.default_rng(7)
    for _ in range(500):
        o = ObjectGeneral(int(rng.integers(256)), round(rng.uniform(-10, 300) / 0.2) * 0.2,
                          round(rng.uniform(-100, 100) / 0.2) * 0.2,
                          round(rng.uniform(-128, 127) / 0.25) * 0.25,
                          round(rng.uniform(-64, 63) / 0.25) * 0.25, int(rng.integers(8)),
                          round(rng.uniform(-64, 63) / 0.5) * 0.5)
        back = decode_frame(*encode(o))[2]
        assert all(math.isclose(a, b, abs_tol=1e-6) for a, b in zip(back, o, strict=True))


def test_encoder_refuses_unrepresentable_values():
    with pytest.raises(EncodeError, match="Obj_DistLong"):
        encode(ObjectGeneral(1, 2000.0, 0.0, 0.0, 0.0, 0, 0.0))
    with pytest.raises(EncodeError, match="Obj_DistLong"):
        encode(ObjectGeneral(1, -50.0, 0.0, 0.0, 0.0, 0, 0.0))   # representable, not valid
    with pytest.raises(EncodeError, match="Obj_Class"):
        encode(ObjectExtended(1, 0.0, 0.0, 7, 0.0, 1.0, 1.0))
    # On purpose (fault injection): the frame is built, and the decoder rejects it.
    bad = encode(ObjectGeneral(1, -50.0, 0.0, 0.0, 0.0, 0, 0.0), validate=False)
    with pytest.raises(RadarFrameError, match="Obj_DistLong"):
        decode_frame(*bad)
    with pytest.raises(EncodeError):
        object_cycle_frames([ObjectGeneral(i % 256, 5.0, 0.0, 0.0, 0.0, 0, 0.0)
                             for i in range(256)], 0)


def test_bad_frames_are_errors_with_a_reason():
    with pytest.raises(RadarFrameError) as err:
        decode_frame(0x60B, bytes(7))
    assert err.value.reason == "wrong_dlc"
    with pytest.raises(RadarFrameError) as err:
        decode_frame(0x60B, bytes(9))
    assert err.value.reason == "wrong_dlc"
    with pytest.raises(RadarFrameError) as err:
        decode_frame(0x60B, bytes(8))             # DistLong raw 0 = -500 m
    assert err.value.reason == "out_of_range" and "Obj_DistLong" in str(err.value)
    with pytest.raises(RadarFrameError) as err:
        decode_frame(0x123, bytes(8))
    assert err.value.reason == "unknown_id"
    # Longer-than-needed frames of short messages still decode (DLC 7 quality in 8 bytes).
    assert decode_frame(0x60C, bytes.fromhex("3884A33A0220E800"))[2].prob_of_exist == 7


def test_cycle_encoders_order_and_counts():
    objs = [ObjectGeneral(i, 10.0 + i, 0.0, -1.0, 0.0, 0, 5.0) for i in range(3)]
    qual = [ObjectQuality(i, 1, 1, 1, 1, 2, 7) for i in range(3)]
    ext = [ObjectExtended(i, 0.0, 0.0, 1, 0.0, 4.0, 1.8) for i in range(3)]
    frames = object_cycle_frames(objs, 65537, qual, ext, sensor_id=1)
    assert [f.arb_id for f in frames] == [0x61A] + [0x61B] * 3 + [0x61C] * 3 + [0x61D] * 3
    assert decode_frame(*frames[0])[2] == ObjectListStatus(3, 1, 1)
    clusters = [ClusterGeneral(i, 5.0, 0.0, 0.0, 0.0, 0, 0.0) for i in range(4)]
    frames = cluster_cycle_frames(clusters, 9, n_near=1)
    assert decode_frame(*frames[0])[2] == ClusterListStatus(1, 3, 9, 1)
    assert [f.arb_id for f in frames[1:]] == [0x701] * 4
    with pytest.raises(ValueError):
        object_cycle_frames(objs, 0, qual[:2])


def test_ego_motion_frames():
    speed, yaw = ego_motion_frames(-2.5, 10.0, sensor_id=1)
    assert speed.arb_id == 0x310 and yaw.arb_id == 0x311
    assert decode_frame(*speed)[2] == pytest.approx(SpeedInformation(2, 2.5))
    assert decode_frame(*yaw)[2].yaw_rate_dps == pytest.approx(10.0)
    assert decode_frame(*ego_motion_frames(0.005, 0.0)[0])[2].direction == 0   # standstill
    assert decode_frame(*ego_motion_frames(13.9, -3.3)[0])[2] == pytest.approx(
        SpeedInformation(1, 13.9))
    with pytest.raises(EncodeError):
        ego_motion_frames(200.0, 0.0)


def test_shipped_dbc_is_generated_from_the_table():
    assert DBC_PATH.read_text(encoding="utf-8") == render(), \
        "run: python -m aeb_radar_camera.services.radar.ars408.dbc --write"
    text = render()
    # Spot checks of DBC conventions: Motorola start bit = MSB, DistLat left positive.
    assert " SG_ Obj_DistLong : 15|13@0+ (0.2,-500) [-500|1138.2] \"m\" HOST" in text
    assert " SG_ Obj_DistLat : 18|11@0+ (0.2,-204.6) [-204.6|204.8] \"m\" HOST" in text
    assert " SG_ Cluster_DistLat : 17|10@0+ (0.2,-102.3)" in text
    assert f"BO_ {0x200} RadarCfg: 8 HOST" in text


def test_frame_type_is_a_plain_tuple():
    f = RadarFrame(0x60B, b"\x00" * 8)
    assert f == (0x60B, b"\x00" * 8) and BY_KIND[Kind.OBJECT_GENERAL].base_id == 0x60B


@pytest.mark.parametrize("spec", MESSAGES, ids=lambda m: m.dbc_name)
def test_short_lists_decode_as_their_frames_one_by_one(spec):
    """A cycle's lists are often one to four frames: decode_columns on those gives each
    frame's scalar decode, frames of mixed lengths (up to 8 bytes) and rejections included."""
    rng = np.random.default_rng(spec.base_id + 1)
    edges = [bytes(spec.dlc), b"\xff" * spec.dlc, b"\xaa" * spec.dlc, b"\x55" * spec.dlc]
    lists = [edges, [b"\xff" * 8][:1] if spec.dlc == 8 else [b"\xff" * spec.dlc + b"\x01"]]
    for _ in range(200):
        n = int(rng.integers(1, 5))
        # DLC-checked payloads: the message's DLC up to 8 bytes (longer ones are padded)
        lists.append([bytes(rng.integers(0, 256, int(rng.integers(spec.dlc, 9)),
                                         dtype=np.uint8)) for _ in range(n)])
    bad_frames = 0
    for datas in lists:
        cols = decode_columns(spec, datas)
        rejected: dict[str, int] = {}
        for k, data in enumerate(datas):
            try:
                record = decode(spec, data)
            except RadarFrameError as exc:
                assert exc.reason == "out_of_range" and not cols.valid[k]
                key = "out_of_range:" + str(exc).split(": ", 1)[1].split("=")[0]
                rejected[key] = rejected.get(key, 0) + 1
                continue
            assert cols.valid[k]
            assert [float(cols.values[a][k]) for a in record._fields] == list(record)
        assert cols.rejected == rejected and cols.all_valid == (not rejected)
        bad_frames += len(datas) - int(cols.valid.sum())
    if any(s.valid is not None for s in spec.signals):
        assert bad_frames > 0, "no out-of-range frame drawn: the rejection path is untested"
