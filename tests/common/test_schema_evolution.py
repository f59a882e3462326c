"""The schema evolution rule (docs/architecture.md): a newer publisher that adds a field
with a default must not break an older subscriber, and an older publisher must not break
a newer subscriber. Breaking changes bump the schema version, which is rejected."""

import msgspec
import pytest

from aeb_radar_camera.common.messages import (
    SCHEMA_VERSION,
    DecodeError,
    Header,
    OutputMode,
    RadarTrack,
    RadarTracks,
    decode,
    encode,
)
from aeb_radar_camera.common.messages.schema import zenoh_encoding
from tests.messages_support import example, message_types

TYPES = message_types()


# What a newer release of the radar might publish: one field more in the track, the cycle
# and the header, each with a default so that the newer type still reads older messages.
class NewerHeader(Header, frozen=True):
    clock_source: str = "ptp"


class NewerRadarTrack(RadarTrack, frozen=True):
    elevation_m: float = 0.0


class NewerRadarTracks(msgspec.Struct, frozen=True):
    header: NewerHeader
    sensor: str
    mode: OutputMode
    meas_counter: int
    complete: bool
    n_detections: int
    n_prefiltered: int
    last_frame_mono_ns: int
    processing_ns: int
    tracks: tuple[NewerRadarTrack, ...]
    cycle_time_ms: float = 72.0


def newer_tracks() -> NewerRadarTracks:
    track = NewerRadarTrack(track_id=4, x_m=11.4, y_m=-0.2, vx_mps=-3.0, vy_mps=0.0,
                            range_m=11.4, range_rate_mps=-3.0, rcs_dbsm=27.0, confirmed=True,
                            hits=5, misses=0, x_var_m2=0.1, y_var_m2=0.1, elevation_m=0.4)
    return NewerRadarTracks(
        header=NewerHeader(seq=9, source="radar/front", stamp_ns=1, pub_mono_ns=2,
                           clock_source="gps"),
        sensor="front", mode=OutputMode.OBJECTS, meas_counter=3, complete=True,
        n_detections=2, n_prefiltered=1, last_frame_mono_ns=5, processing_ns=6,
        tracks=(track,), cycle_time_ms=71.5)


def test_an_older_subscriber_decodes_a_newer_publishers_message():
    newer = newer_tracks()
    old = decode(encode(newer), RadarTracks)     # what today's fusion does with it
    assert old.meas_counter == 3 and old.header.seq == 9
    (track,) = old.tracks
    assert (track.track_id, track.range_m, track.range_rate_mps) == (4, 11.4, -3.0)
    assert not hasattr(track, "elevation_m")


def test_a_newer_subscriber_decodes_an_older_publishers_message_with_the_defaults():
    newer = decode(encode(decode(encode(newer_tracks()), RadarTracks)), NewerRadarTracks)
    assert newer.cycle_time_ms == 72.0
    assert newer.tracks[0].elevation_m == 0.0
    assert newer.header.clock_source == "ptp"


@pytest.mark.parametrize("msg_type", TYPES, ids=lambda t: t.__name__)
def test_every_message_type_ignores_fields_it_does_not_know(msg_type):
    sample = example(msg_type)
    as_map = msgspec.msgpack.decode(encode(sample))
    assert isinstance(as_map, dict)          # keyed by field name: never array_like
    as_map["added_in_a_newer_release"] = {"nested": [1, 2.5, "three"]}
    if "header" in as_map:
        as_map["header"]["added_too"] = 1
    assert decode(msgspec.msgpack.encode(as_map), msg_type) == sample


@pytest.mark.parametrize("msg_type", TYPES, ids=lambda t: t.__name__)
def test_a_breaking_change_is_a_new_schema_version_and_is_rejected(msg_type):
    as_map = msgspec.msgpack.decode(encode(example(msg_type)))
    if "header" not in as_map:
        pytest.fail(f"{msg_type.__name__} has no header, so no schema version")
    as_map["header"]["schema"] = SCHEMA_VERSION + 1
    with pytest.raises(DecodeError, match="schema version"):
        decode(msgspec.msgpack.encode(as_map), msg_type)


def test_a_changed_field_type_still_fails_loudly():
    # adding is safe; retyping is not, and the subscriber says so instead of misreading
    as_map = msgspec.msgpack.decode(encode(example(RadarTracks)))
    as_map["meas_counter"] = "three"
    with pytest.raises(DecodeError, match="meas_counter"):
        decode(msgspec.msgpack.encode(as_map), RadarTracks)


def test_the_encoding_names_the_message_type():
    assert zenoh_encoding(RadarTracks) == "application/msgpack;aeb.RadarTracks"
