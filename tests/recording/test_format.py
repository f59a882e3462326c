"""The recording format in-process: writer and reader, splitting, a file whose recorder
was killed, a file that is not a recording, and the channels' schemas."""

import json

import msgspec
import pytest

from aeb_radar_camera.common.messages import CompressedFrame, RadarTracks, encode
from aeb_radar_camera.tools.recording.format import (
    UNKNOWN_CHANNEL,
    channel_of_topic,
    parse_topic,
    publish_time,
    stack_channel,
)
from aeb_radar_camera.tools.recording.reader import Recording, RecordingError, decode_record
from aeb_radar_camera.tools.recording.writer import RecordingWriter
from tests.system.messages import header, radar_tracks, track

TRACKS = "aeb/ego/radar/front/tracks"
FRAMES = "aeb/ego/camera/front/jpeg"


def decoded(r):
    d = decode_record(r)
    assert d is not None
    return d


def frame(i: int, size: int = 2000) -> bytes:
    return encode(CompressedFrame(header=header(i, "camera/front", 1_000 + i), camera="front",
                                  width=848, height=480, jpeg=bytes([i % 256]) * size))


def write(writer: RecordingWriter, n: int, step_ns: int = 10_000_000) -> None:
    for i in range(n):
        t = 10**18 + i * step_ns
        writer.write(FRAMES, channel_of_topic(FRAMES), frame(i), t, 1_000 + i, i)
        if i % 2:
            msg = radar_tracks(i // 2, (track(1, 10.0),), stamp_ns=t - 5)
            writer.write(TRACKS, stack_channel(RadarTracks), encode(msg), t, t - 5, i // 2)


def test_every_record_round_trips_with_its_times_and_schema(tmp_path):
    path = tmp_path / "a.mcap"
    with RecordingWriter(path, metadata={"vehicle": "ego"}) as w:
        write(w, 40)
    rec = Recording.open(path)
    channels = rec.channels()
    assert channels[FRAMES].messages == 40 and channels[TRACKS].messages == 20
    assert channels[TRACKS].schema_name == "aeb.RadarTracks"
    assert channels[TRACKS].message_encoding == "msgpack"
    assert rec.metadata() == {"vehicle": "ego"}
    records = list(rec.records())
    assert [r.log_time_ns for r in records] == sorted(r.log_time_ns for r in records)
    tracks = [r for r in records if r.topic == TRACKS]
    info, msg = decoded(tracks[3])
    assert info.spec.name == "radar_tracks" and msg.header.seq == 3
    assert tracks[3].publish_time_ns == msg.header.stamp_ns == tracks[3].log_time_ns - 5
    assert rec.time_range() == (10**18, 10**18 + 39 * 10_000_000)
    only = list(rec.records([TRACKS], start_ns=10**18 + 100_000_000))
    assert {r.topic for r in only} == {TRACKS} and len(only) == 15


def test_schemas_are_msgspecs_json_schema_of_the_message():
    kind = stack_channel(RadarTracks)
    assert kind.schema_encoding == "jsonschema" and kind.message_encoding == "msgpack"
    assert json.loads(kind.schema_data) == msgspec.json.schema(RadarTracks)
    assert channel_of_topic("aeb/ego/some/new/key") is UNKNOWN_CHANNEL
    info = parse_topic("aeb/car2/fusion/candidate/brake_cmd")
    assert info is not None and info.params == {"instance": "candidate"}
    assert parse_topic("/foxglove/ego/health") is None
    assert publish_time(frame(3), 7) == 1_003 and publish_time(b"\x01junk", 7) == 7


def test_splitting_by_size_and_duration_makes_numbered_files_that_read_as_one(tmp_path):
    with RecordingWriter(tmp_path / "s.mcap", split_bytes=20_000) as w:
        write(w, 60)
    files = sorted(tmp_path.glob("s_*.mcap"))
    assert len(files) >= 4 and files[0].name == "s_0000.mcap"
    rec = Recording.open(tmp_path)
    assert sum(1 for r in rec.records() if r.topic == FRAMES) == 60
    for f in files:      # each file opens on its own, schemas included
        assert Recording.open(f).channels()[FRAMES].schema_name == "aeb.CompressedFrame"
    with RecordingWriter(tmp_path / "d" / "t.mcap", split_s=0.1) as w:
        write(w, 60)     # 10 ms apart: 0.6 s
    assert len(list((tmp_path / "d").glob("t_*.mcap"))) == 6


def test_a_file_whose_recorder_was_killed_reads_up_to_its_last_chunk(tmp_path):
    path = tmp_path / "k.mcap"
    w = RecordingWriter(path, chunk_bytes=10_000)
    write(w, 50)
    w.flush()
    data = path.read_bytes()          # no close(): no summary, no index
    path.write_bytes(data[: len(data) - 3000])
    rec = Recording.open(path)
    got = [r for r in rec.records() if r.topic == FRAMES]
    assert 25 <= len(got) < 50
    assert [decoded(r)[1].header.seq for r in got] == list(range(len(got)))
    assert rec.truncated == [path]
    assert rec.channels()[FRAMES].messages == len(got)


def test_what_is_not_a_recording_is_said_so(tmp_path):
    text = tmp_path / "notes.txt"
    text.write_text("not a recording\n")
    with pytest.raises(RecordingError, match="is not an MCAP recording"):
        Recording.open(text)
    (tmp_path / "empty.mcap").write_bytes(b"")
    with pytest.raises(RecordingError, match="is not an MCAP recording"):
        Recording.open(tmp_path / "empty.mcap")
    with pytest.raises(RecordingError, match="no such file"):
        Recording.open(tmp_path / "missing.mcap")
    (tmp_path / "dir").mkdir()
    with pytest.raises(RecordingError, match=r"no \.mcap file"):
        Recording.open(tmp_path / "dir")
