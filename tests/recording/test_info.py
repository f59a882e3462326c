"""`aeb info`: what a recording holds, as `ros2 bag info` says it; counts agree with the
file's own summary, messages missing from a publisher's numbering are said per channel,
and a recording whose recorder was killed is said to be truncated."""

import json
import subprocess

import msgspec

from aeb_radar_camera.common.messages import BrakeCommand, encode
from aeb_radar_camera.tools.recording.format import stack_channel
from aeb_radar_camera.tools.recording.info import inspect
from aeb_radar_camera.tools.recording.reader import Recording
from aeb_radar_camera.tools.recording.writer import RecordingWriter
from tests.messages_support import example
from tests.support import REPO, python_module

SIM = REPO / "tests" / "data" / "recording" / "pedestrian_standing_20kph.mcap"
CMD = "aeb/ego/fusion/primary/brake_cmd"


def info(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(python_module("aeb_radar_camera.tools.cli", "info", *args),
                          capture_output=True,
                          text=True, timeout=120, cwd=REPO)


def test_info_on_the_kept_recording_agrees_with_its_summary():
    proc = info(str(SIM), "--json")
    assert proc.returncode == 0, proc.stderr
    said = json.loads(proc.stdout)
    channels = Recording.open(SIM).channels()
    assert {c["topic"]: c["messages"] for c in said["channels"]} == {
        t: c.messages for t, c in channels.items()}
    cmd = next(c for c in said["channels"] if c["topic"] == CMD)
    assert cmd["type"] == "aeb.BrakeCommand" and cmd["encoding"] == "msgpack"
    assert 13.0 < cmd["rate_hz"] < 14.0 and cmd["dropped"] == 0       # one per radar cycle
    assert 7.0 < said["duration_s"] < 8.0 and said["truncated"] == []
    text = info(str(SIM)).stdout
    assert "Duration:   7.497 s" in text and "Truncated:  no" in text
    assert "/foxglove/ego/camera/front/image" in text and "foxglove.CompressedImage" in text


def _commands(path, seqs, close=True):
    writer = RecordingWriter(path, metadata={"vehicle": "ego", "recorder": "test"})
    base = example(BrakeCommand)
    for i, seq in enumerate(seqs):
        msg = msgspec.structs.replace(base, header=msgspec.structs.replace(base.header,
                                                                          seq=seq))
        writer.write(CMD, stack_channel(BrakeCommand), encode(msg), 10**18 + i * 75_000_000,
                     10**18, seq)
    if close:
        writer.close()
    else:
        writer.flush()
        assert writer._file is not None
        writer._file.close()              # as a killed recorder leaves it
    return path


def test_messages_missing_from_the_numbering_are_dropped_and_a_restart_is_not(tmp_path):
    # 3 and 5, 6 never arrived; at 0 the publisher restarted: nothing lost there
    got = inspect(Recording.open(_commands(tmp_path / "gaps.mcap", [1, 2, 4, 7, 0, 1])))
    (cmd,) = got.channels
    assert cmd.messages == 6 and cmd.dropped == 3 and got.dropped == 3
    assert cmd.rate_hz is not None and abs(cmd.rate_hz - 1 / 0.075) < 1e-6
    text = info(str(tmp_path / "gaps.mcap")).stdout
    assert f"Dropped:    3 ({CMD} 3)" in text


def test_a_recording_whose_recorder_was_killed_is_said_truncated(tmp_path):
    path = _commands(tmp_path / "killed.mcap", range(40), close=False)
    proc = info(str(path))
    assert proc.returncode == 0, proc.stderr
    assert f"Truncated:  {path}" in proc.stdout


def test_not_a_recording_is_exit_2():
    proc = info(str(REPO / "README.md"))
    assert proc.returncode == 2 and "not an MCAP recording" in proc.stderr
