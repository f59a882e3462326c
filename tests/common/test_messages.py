import msgspec
import pytest

from aeb_radar_camera.common.messages import (
    BrakeCommand,
    Decision,
    DecodeError,
    Header,
    RadarTrack,
    RadarTracks,
    VerifierStatus,
    decode,
    encode,
)
from aeb_radar_camera.common.messages.radar import OutputMode
from tests.messages_support import example


def header(seq: int = 3) -> Header:
    return Header(seq=seq, source="fusion/primary", stamp_ns=1_700_000_000_000_000_000,
                  pub_mono_ns=42)


def command() -> BrakeCommand:
    return BrakeCommand(
        header=header(), instance="primary", decision=Decision.BRAKE, brake_level_pct=80.0,
        verifier_status=VerifierStatus.OK, held=False, track_id=7, range_m=9.5, ttc_s=1.2,
        reason="verified in path", radar_seq=11, radar_last_frame_mono_ns=41,
    )


def test_round_trip_keeps_every_field():
    cmd = command()
    assert decode(encode(cmd), BrakeCommand) == cmd


def test_tracks_round_trip_with_nested_structs():
    track = RadarTrack(track_id=1, x_m=11.4, y_m=-0.2, vx_mps=0.0, vy_mps=0.0, range_m=11.4,
                       range_rate_mps=0.0, rcs_dbsm=27.0, confirmed=True, hits=5, misses=0,
                       x_var_m2=0.1, y_var_m2=0.1, radar_object_id=56)
    msg = RadarTracks(header=header(), sensor="front", mode=OutputMode.OBJECTS, meas_counter=9,
                      complete=True, n_detections=3, n_prefiltered=2, last_frame_mono_ns=5,
                      processing_ns=100, tracks=(track,))
    assert decode(encode(msg), RadarTracks).tracks[0] == track


@pytest.mark.parametrize("payload", [b"", b"\xc1", b"not msgpack at all", encode(header())])
def test_garbage_raises_decode_error_naming_the_type(payload):
    with pytest.raises(DecodeError, match="BrakeCommand"):
        decode(payload, BrakeCommand)


def test_other_schema_version_is_rejected():
    cmd = msgspec.structs.replace(command(), header=msgspec.structs.replace(header(), schema=99))
    with pytest.raises(DecodeError, match="schema version 99"):
        decode(encode(cmd), BrakeCommand)

# An unknown field is a newer publisher's addition: tests/common/test_schema_evolution.py



def struct_types() -> list[type[msgspec.Struct]]:
    """Every message struct defined in common/messages/, nested ones included."""
    import aeb_radar_camera.common.messages as package

    found = {c for name in dir(package)
             if isinstance(c := getattr(package, name), type) and issubclass(c, msgspec.Struct)}
    return sorted(found, key=lambda c: c.__name__)


# The tracker builds hundreds of RadarTracks per cycle: 16 keyword arguments cost CPython
# about five times a positional call.
POSITIONAL_ALLOWED = {"RadarTrack"}


@pytest.mark.parametrize("msg_type", [t for t in struct_types()
                                      if len(t.__struct_fields__) >= 6],
                         ids=lambda t: t.__name__)
def test_messages_with_many_fields_are_built_by_field_name(msg_type):
    sample = example(msg_type)
    values = [getattr(sample, f) for f in msg_type.__struct_fields__]
    assert msg_type(**dict(zip(msg_type.__struct_fields__, values, strict=True))) == sample
    if msg_type.__name__ in POSITIONAL_ALLOWED:
        assert msg_type(*values) == sample
    else:
        with pytest.raises(TypeError):
            msg_type(*values)


def test_no_message_is_tracked_by_the_garbage_collector():
    """Messages are trees: kept by the thousand (a history, an observer), tracked ones
    would lengthen every full collection, a pause for every thread of the process."""
    import gc

    import aeb_radar_camera.common.messages as messages

    types = [t for t in vars(messages).values()
             if isinstance(t, type) and issubclass(t, msgspec.Struct)]
    assert len(types) >= 15
    for tp in types:
        value = decode(encode(example(tp)), tp)
        assert not gc.is_tracked(value), tp.__name__
