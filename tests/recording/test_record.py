"""`aeb record` as a user runs it, beside a publishing stack: every key, nothing lost,
what it wrote said on exit, the Foxglove views valid for Foxglove's schemas, a clean file
after Ctrl-C or SIGTERM, a readable one after SIGKILL, split files, and Ctrl-C while no
router answers yet."""

import json
import signal
import subprocess
import time

import pytest

from aeb_radar_camera.common.messages import Header
from aeb_radar_camera.common.net import free_port
from aeb_radar_camera.tools.recording.reader import Recording, decode_record
from aeb_radar_camera.tools.recording.record import default_name
from aeb_radar_camera.tools.recording.recorder import RECORDER_STATUS
from aeb_radar_camera.tools.recording.writer import RecordingWriter
from tests.foxglove.protobuf import decode as decode_protobuf
from tests.recording.publish import StackPublisher
from tests.support import (
    START_TIMEOUT_S,
    HealthWatch,
    ServiceProcess,
    open_bus,
    python_module,
    wait_for,
)

pytestmark = pytest.mark.slow

STACK_KEYS = {
    "aeb/ego/camera/front/jpeg", "aeb/ego/camera/front/info", "aeb/ego/radar/front/tracks",
    "aeb/ego/radar/front/status", "aeb/ego/can/radar/frames",
    "aeb/ego/fusion/primary/targets", "aeb/ego/fusion/primary/brake_cmd",
    "aeb/ego/brake/status",
}


def start_recorder(router, tmp_path, *extra, name="record"):
    out = tmp_path / f"{name}.mcap"
    proc = ServiceProcess(name, python_module(
        "aeb_radar_camera.tools.cli", "record", "-o", str(out), "--connect", router,
        "--summary-json", str(tmp_path / f"{name}.json"), *extra), tmp_path)
    return proc, out


def wait_recorded(bus, proc, expected: dict[str, int]) -> None:
    """Until the recorder's status says it wrote `expected` (its queryable: no sleep)."""
    def done():
        for status, _ in bus.query(RECORDER_STATUS, 2.0, instance=str(proc.pid)):
            if status.queued == 0 and all(status.messages.get(k, 0) >= n
                                          for k, n in expected.items()):
                return True
        return False

    wait_for(done, START_TIMEOUT_S, 0.1, "the recorder to write everything published")


def record_stack(router, tmp_path, *extra, cycles=40, name="record", recorded=None):
    """Record `cycles` of the publisher; returns once the recorder wrote them all (all
    keys, or those in `recorded`)."""
    proc, out = start_recorder(router, tmp_path, *extra, name=name)
    with open_bus(router, source="test") as bus:
        HealthWatch(bus).wait_alive("record", str(proc.pid), START_TIMEOUT_S)
        pub = StackPublisher(bus, cycles=cycles).start()
        pub.join(60)
        published = pub.published.counts
        wait_recorded(bus, proc, {k: n for k, n in published.items()
                                  if recorded is None or k in recorded})
    return proc, out, published


def test_every_key_is_recorded_nothing_is_lost_and_the_summary_says_so(router, tmp_path):
    proc, out, published = record_stack(router, tmp_path)
    proc.signal(signal.SIGINT)
    assert proc.proc.wait(30) == 0, proc.output()
    log = proc.output()
    assert "wrote 1 file(s)" in log and "aeb/ego/camera/front/jpeg" in log
    summary = json.loads((tmp_path / "record.json").read_text())
    assert {k: v["messages"] for k, v in summary["keys"].items()
            if k in published} == published
    assert all(v["dropped"] == 0 for v in summary["keys"].values())
    rec = Recording.open(out)
    channels = rec.channels()
    assert set(channels) >= STACK_KEYS
    for key, n in published.items():
        assert channels[key].messages == n, key
        assert channels[key].schema_name.startswith("aeb.")
        assert channels[key].message_encoding == "msgpack"
    seqs: dict[str, list[int]] = {}
    for r in rec.records(list(published)):
        decoded = decode_record(r)          # every payload decodes with its type
        assert decoded is not None
        msg = decoded[1]
        assert r.publish_time_ns == msg.header.stamp_ns
        seqs.setdefault(r.topic, []).append(msg.header.seq)
    assert all(s == sorted(s) and s == list(range(s[0], s[0] + len(s)))
               for s in seqs.values())


def test_the_views_decode_with_foxglove_schemas(router, tmp_path):
    proc, out, _ = record_stack(router, tmp_path, cycles=12)
    proc.stop()
    rec = Recording.open(out)
    schemas = {}
    with open(out, "rb") as f:
        from mcap.reader import make_reader

        summary = make_reader(f).get_summary()
        assert summary is not None
        for ch in summary.channels.values():
            s = summary.schemas.get(ch.schema_id)
            if s is not None:
                schemas[ch.topic] = (s.name, s.encoding, s.data, ch.message_encoding)
    image = "/foxglove/ego/camera/front/image"
    ann = "/foxglove/ego/fusion/primary/annotations/front"
    scene = "/foxglove/ego/fusion/primary/scene"
    radar = "/foxglove/ego/radar/front/scene"
    assert schemas[image][:2] == ("foxglove.CompressedImage", "protobuf")
    assert schemas[ann][:2] == ("foxglove.ImageAnnotations", "protobuf")
    assert schemas[scene][:2] == schemas[radar][:2] == ("foxglove.SceneUpdate", "protobuf")
    image_stamps = set()
    for r in rec.records([image]):
        msg = decode_protobuf(schemas[image][0], schemas[image][2], r.data)
        assert msg.format == "jpeg" and msg.data[:2] == b"\xff\xd8"
        image_stamps.add(msg.timestamp.seconds * 10**9 + msg.timestamp.nanos)
    anns = [decode_protobuf(schemas[ann][0], schemas[ann][2], r.data)
            for r in rec.records([ann])]
    assert anns and all(len(a.points) == 1 and len(a.points[0].points) == 4 for a in anns)
    # On the frame each ROI was checked in: an image of the recording has its stamp.
    stamps = {a.points[0].timestamp.seconds * 10**9 + a.points[0].timestamp.nanos
              for a in anns}
    assert stamps <= image_stamps
    for r in rec.records([scene]):
        update = decode_protobuf(schemas[scene][0], schemas[scene][2], r.data)
        ids = {e.id for e in update.entities}
        assert {"corridor", "track-1"} <= ids and update.deletions
    threat = json.loads(next(rec.records(["/foxglove/ego/fusion/primary/threat"])).data)
    assert threat["track_id"] == 1 and schemas["/foxglove/ego/fusion/primary/threat"][3] \
        == "json"


def test_sigterm_leaves_a_complete_file_and_sigkill_a_readable_one(router, tmp_path):
    proc, out, _ = record_stack(router, tmp_path, cycles=15, name="term")
    proc.signal(signal.SIGTERM)
    assert proc.proc.wait(30) == 0
    rec = Recording.open(out)
    assert rec.truncated == [] and rec.channels()["aeb/ego/radar/front/tracks"].messages == 15
    # Killed: the chunks written so far are read (2 s flush), the rest is gone.
    proc, out, _published = record_stack(router, tmp_path, "--compression", "lz4",
                                        cycles=60, name="kill")
    proc.signal(signal.SIGKILL)
    proc.proc.wait(30)
    rec = Recording.open(out)
    n = sum(1 for _ in rec.records(["aeb/ego/radar/front/tracks"]))
    assert rec.truncated == [out] and 0 < n <= 60


def test_split_by_duration_gives_numbered_files_that_read_as_one(router, tmp_path):
    proc, _out, _published = record_stack(router, tmp_path, "--split-duration", "1", cycles=30,
                                        name="split")
    proc.stop()
    files = sorted(tmp_path.glob("split_*.mcap"))
    assert len(files) >= 2
    rec = Recording.open(files)
    assert rec.channels()["aeb/ego/radar/front/tracks"].messages == 30


def test_keys_select_what_is_recorded(router, tmp_path):
    keys = {"aeb/ego/radar/front/tracks", "aeb/ego/fusion/primary/brake_cmd"}
    proc, out, _published = record_stack(router, tmp_path, "--keys",
                                        "radar_tracks,fusion/*/brake_cmd", "--no-views",
                                        cycles=10, name="keys", recorded=keys)
    proc.stop()
    assert set(Recording.open(out).channels()) == keys


def test_ctrl_c_while_no_router_answers_ends_it_at_once(tmp_path):
    proc, _ = start_recorder(f"tcp/127.0.0.1:{free_port()}", tmp_path)
    try:
        wait_for(lambda: "waiting_for_router" in proc.output(), START_TIMEOUT_S, 0.05,
                 "the recorder to say what it waits for")
        proc.signal(signal.SIGINT)
        assert proc.proc.wait(10) == 0
        assert "Traceback" not in proc.output()
    finally:
        proc.stop()


@pytest.mark.parametrize("split", [False, True])
def test_an_existing_recording_is_never_overwritten(tmp_path, split):
    # refused before the bus is opened: no router needed, the file untouched
    out = tmp_path / "drive.mcap"
    existing = tmp_path / "drive_0000.mcap" if split else out
    existing.write_bytes(b"a drive worth keeping")
    argv = ["record", "-o", str(out), "--connect", f"tcp/127.0.0.1:{free_port()}",
            *(["--split-duration", "60"] if split else [])]
    done = subprocess.run(python_module("aeb_radar_camera.tools.cli", *argv), capture_output=True,
                          text=True,
                          timeout=60, cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert f"{existing} already exists" in done.stderr and "never overwrites" in done.stderr
    assert existing.read_bytes() == b"a drive worth keeping"


def test_the_default_name_is_the_start_date_and_time():
    now = time.mktime((2026, 12, 2, 15, 18, 8, 0, 0, -1))
    assert default_name(now) == "aeb_2026_12_02-15_18_08.mcap"


def test_the_writer_refuses_a_file_that_appeared_meanwhile(tmp_path):
    out = tmp_path / "late.mcap"
    writer = RecordingWriter(out, exclusive=True)
    out.write_bytes(b"another recorder's")
    with pytest.raises(FileExistsError):
        writer.write_message("aeb/ego/x", Header(seq=1, source="t", stamp_ns=1,
                                                  pub_mono_ns=1), 1)
    assert out.read_bytes() == b"another recorder's"
