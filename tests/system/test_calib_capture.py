"""`aeb calib-capture` pairs a camera frame with the radar cycle nearest to it in time,
from the live bus, and saves what `aeb calib-check` reads."""

import json
import subprocess
import sys
import threading

import msgspec
import pytest

from aeb_radar_camera.common.imaging import encode_jpeg
from aeb_radar_camera.common.keys import CAMERA_JPEG, RADAR_TRACKS
from aeb_radar_camera.common.messages import CompressedFrame, RadarTracks
from aeb_radar_camera.tools.calib import check as calib_check
from aeb_radar_camera.tools.calib.capture import Pairing
from aeb_radar_camera.tools.sim.scenes import Obstacle, Scene, render
from tests.fusion.helpers import CAL, CALIBRATION, cycle, track
from tests.support import open_bus

MS = 1_000_000
T0 = 1_800_000_000 * 10**9


def frame(stamp_ns: int, seq: int = 0, jpeg: bytes = b"\xff\xd8") -> CompressedFrame:
    from aeb_radar_camera.common.messages import Header

    return CompressedFrame(header=Header(seq=seq, source="camera/front", stamp_ns=stamp_ns,
                                         pub_mono_ns=0), camera="front", width=848, height=480,
                           jpeg=jpeg)


def tracks_at(stamp_ns: int, seq: int = 0) -> RadarTracks:
    msg = cycle(track(1, 8.0, 0.8))
    return msgspec.structs.replace(msg, header=msgspec.structs.replace(
        msg.header, stamp_ns=stamp_ns, seq=seq))


# -- the pairing, pure ------------------------------------------------------------------

def test_the_nearest_cycle_wins_whether_before_or_after_the_frame():
    p = Pairing(max_skew_ns=50 * MS)
    assert p.add_cycle(tracks_at(T0, 1)) is None
    assert p.add_frame(frame(T0 + 60 * MS)) is None         # the cycle after may be nearer
    pair = p.add_cycle(tracks_at(T0 + 75 * MS, 2))
    assert pair is not None and pair.tracks.header.seq == 2 and pair.skew_ns == 15 * MS
    p = Pairing(max_skew_ns=50 * MS)
    p.add_cycle(tracks_at(T0, 1))
    p.add_frame(frame(T0 + 10 * MS))
    pair = p.add_cycle(tracks_at(T0 + 75 * MS, 2))
    assert pair is not None and pair.tracks.header.seq == 1 and pair.skew_ns == -10 * MS


def test_a_frame_too_far_from_every_cycle_is_counted_and_the_next_one_tried():
    p = Pairing(max_skew_ns=20 * MS)
    p.add_cycle(tracks_at(T0))
    p.add_frame(frame(T0 + 40 * MS))
    assert p.add_cycle(tracks_at(T0 + 100 * MS)) is None    # 40 and 60 ms: both too far
    assert p.too_far == 1
    pair = p.add_frame(frame(T0 + 95 * MS))                   # 5 ms before the last cycle
    assert pair is not None and pair.skew_ns == 5 * MS


def test_a_frame_older_than_every_cycle_seen_waits_for_the_next_frame():
    # its previous cycle was missed (the capture started between the two)
    p = Pairing(max_skew_ns=50 * MS)
    p.add_cycle(tracks_at(T0 + 75 * MS))
    assert p.add_frame(frame(T0 + 30 * MS)) is None
    assert p.add_frame(frame(T0 + 63 * MS)) is None
    assert p.add_cycle(tracks_at(T0 + 150 * MS)) is None      # the frame at 63 was dropped
    pair = p.add_frame(frame(T0 + 96 * MS))                   # between 75 and 150
    assert pair is not None and pair.skew_ns == -21 * MS


def test_a_frame_already_behind_the_newest_cycle_pairs_at_once():
    p = Pairing(max_skew_ns=50 * MS)
    p.add_cycle(tracks_at(T0, 4))
    p.add_cycle(tracks_at(T0 + 75 * MS, 5))
    pair = p.add_frame(frame(T0 + 70 * MS))
    assert pair is not None and pair.tracks.header.seq == 5


# -- on the bus, then calib-check on what it saved --------------------------------------

@pytest.fixture(scope="module")
def scene_jpeg():
    return encode_jpeg(render(CAL, Scene(obstacles=(Obstacle(8, 0.8),), seed=4)), 80)


def test_capture_from_the_bus_then_check(router, tmp_path, capsys, scene_jpeg):
    stop = threading.Event()
    published: list[int] = []                  # cycle stamps

    def publish() -> None:
        # frames every 33 ms, radar cycles every 75 ms, on the same (synthetic) timeline;
        # paced, not waited on
        with open_bus(router, source="pub") as bus:
            cam = bus.publisher(CAMERA_JPEG, camera="front")
            radar = bus.publisher(RADAR_TRACKS, sensor="front")
            t = 0
            while not stop.wait(0.011):
                stamp = T0 + t * MS
                if t % 33 == 0:
                    cam.put(frame(stamp, t, scene_jpeg))
                if t % 75 == 0:
                    published.append(stamp)
                    radar.put(tracks_at(stamp, t))
                t += 1

    thread = threading.Thread(target=publish, daemon=True)
    thread.start()
    try:
        done = subprocess.run([sys.executable, "-m", "aeb_radar_camera.tools.cli", "calib-capture",
                               "--out",
                               str(tmp_path / "cap"), "--connect", router, "--timeout", "60"],
                              capture_output=True, text=True, timeout=120)
    finally:
        stop.set()
        thread.join(10)
    assert done.returncode == 0, done.stderr
    meta = json.loads((tmp_path / "cap/capture.json").read_text())
    nearest = min(published, key=lambda s: abs(s - meta["frame_stamp_ns"]))
    assert meta["radar_stamp_ns"] == nearest
    assert abs(meta["skew_ms"]) <= 37.5                 # half a cycle at most
    assert (tmp_path / "cap/frame.jpg").read_bytes() == scene_jpeg
    assert "check: aeb calib-check" in done.stdout
    rc = calib_check.main(["--calibration", CALIBRATION, "--image", str(tmp_path / "cap/frame.jpg"),
                           "--tracks", str(tmp_path / "cap/tracks.msgpack"),
                           "--out", str(tmp_path / "cap/check.png")])
    assert rc == 0
    rows = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("1 ")]
    assert rows and rows[0].endswith("verified")
    # the readable copy is what calib-check reads too
    rc = calib_check.main(["--calibration", CALIBRATION, "--image", str(tmp_path / "cap/frame.jpg"),
                           "--tracks", str(tmp_path / "cap/tracks.json"),
                           "--out", str(tmp_path / "cap/check2.png")])
    assert rc == 0


def test_nothing_on_the_bus_is_exit_1_saying_what_was_seen(router, tmp_path):
    done = subprocess.run([sys.executable, "-m", "aeb_radar_camera.tools.cli", "calib-capture",
                           "--out",
                           str(tmp_path / "cap"), "--connect", router, "--timeout", "1"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    assert "0 radar cycles seen" in done.stderr
    assert not (tmp_path / "cap").exists()
