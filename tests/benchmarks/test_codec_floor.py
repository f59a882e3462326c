"""The codec floor's relays do the real decoding and encoding: a cycle's frames become
the RadarTracks, the command and the actuator line they stand for."""

from benchmarks.codec_floor import FusionCodec, RadarCodec, brake_line
from benchmarks.floor_relay import CycleEnd
from common.messages import RadarTracks, decode
from services.brake.protocol import Command, HostMode
from services.brake.protocol import decode as decode_line
from services.radar.ars408.records import ObjectGeneral
from services.radar.ars408.transmissions import object_cycle_frames
from tools.sim.can_links import slcan_line

OBJECTS = [
    ObjectGeneral(id=3, dist_long_m=30.0, dist_lat_m=0.4, vrel_long_mps=-6.0,
                  vrel_lat_mps=0.0, dyn_prop=0, rcs_dbsm=10.0),
    ObjectGeneral(id=7, dist_long_m=12.0, dist_lat_m=-1.0, vrel_long_mps=-4.0,
                  vrel_lat_mps=0.25, dyn_prop=0, rcs_dbsm=5.0),
]


def _cycle_lines(objects: list[ObjectGeneral], counter: int) -> list[bytes]:
    return [slcan_line(f).rstrip(b"\r") for f in object_cycle_frames(objects, counter)]


def test_a_cycle_becomes_its_tracks_its_command_and_its_line() -> None:
    radar, end = RadarCodec("front"), CycleEnd(frames_per_object=1)
    done = []
    for line in _cycle_lines(OBJECTS, 41):
        radar.line(line)
        done.append(end.line(line))
    assert done[-1] and not any(done[:-1])

    payload, pub_ns = radar.tracks(end.counter, 1_000, 2_000, lambda: 3_000)
    assert pub_ns == 3_000
    tracks = decode(payload, RadarTracks)
    assert tracks.meas_counter == 41 and tracks.last_frame_mono_ns == 1_000
    assert tracks.header.pub_mono_ns == 3_000 and tracks.processing_ns == 2_000
    assert [t.track_id for t in tracks.tracks] == [3, 7]
    near = tracks.tracks[1]
    assert abs(near.x_m - 12.0) < 0.2 and near.range_rate_mps < 0.0   # decoded, not copied

    cmd_payload, _ = FusionCodec("primary").command(payload, lambda: 4_000)
    line = brake_line(cmd_payload)
    frame = decode_line(line.rstrip(b"\n"))
    assert isinstance(frame, Command)
    assert (frame.seq, frame.level_pct, frame.mode) == (1, 0, HostMode.ARMED)   # NONE


def test_a_new_status_frame_starts_a_new_cycle() -> None:
    radar = RadarCodec("front")
    for line in _cycle_lines(OBJECTS, 1)[:-1]:
        radar.line(line)
    for line in _cycle_lines(OBJECTS[:1], 2):
        radar.line(line)
    tracks = decode(radar.tracks(2, 1, 2, lambda: 3)[0], RadarTracks)
    assert [t.track_id for t in tracks.tracks] == [3]
    assert decode(radar.tracks(3, 1, 2, lambda: 3)[0], RadarTracks).tracks == ()
