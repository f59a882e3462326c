"""The pure publishing core: rate, drop-not-queue, stamps, seq, health, backoff, info."""

import zlib

import numpy as np
import pytest

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.messages import CameraInfo, Header, decode, encode
from aeb_radar_camera.services.camera.core import (
    Backoff,
    CameraCore,
    Health,
    Offer,
    RateGate,
    camera_info,
)
from aeb_radar_camera.services.camera.source import Frame
from tests.camera.helpers import CALIBRATION

MS = 1_000_000


def frame(stamp_ns: int, w: int = 64, h: int = 48, value: int = 0) -> Frame:
    return Frame(image=np.full((h, w, 3), value, np.uint8), stamp_ns=stamp_ns)


def test_rate_gate_passes_a_jittery_source_at_the_rate_and_thins_a_faster_one():
    gate = RateGate(25.0)   # 40 ms
    jitter = [0, 3, -4, 5, -2, 4, 0, -5]
    admitted = [gate.admit(i * 40 * MS + j * MS) for i, j in enumerate(jitter)]
    assert all(admitted)

    gate = RateGate(25.0)
    times = [i * 10 * MS for i in range(40)]   # a 100 Hz source
    kept = [t for t in times if gate.admit(t)]
    # Slots every 40 ms; a frame up to a quarter period early takes its slot.
    assert kept == [0] + [t * MS for t in range(30, 400, 40)]


def test_rate_gate_restarts_after_a_gap_without_a_burst():
    gate = RateGate(10.0)
    assert gate.admit(0)
    assert gate.admit(100 * MS)
    # 1 s gap: the next frame is admitted, the one right after is not (no catch-up).
    assert gate.admit(1100 * MS)
    assert not gate.admit(1110 * MS)
    assert gate.admit(1200 * MS)


def test_slot_keeps_only_the_newest_frame_and_counts_drops():
    core = CameraCore("front", 64, 48, fps=1000.0)
    for i in range(5):
        assert core.offer(frame(1000 + i), now_mono_ns=i * 10 * MS) is Offer.PENDING
    taken = core.take()
    assert taken is not None and taken.stamp_ns == 1004   # newest, not oldest
    assert core.take() is None                            # nothing queued behind it
    assert core.stats.dropped == 4
    assert core.stats.captured == 5


def test_messages_carry_capture_stamp_and_gapless_seq_from_zero():
    core = CameraCore("front", 64, 48, fps=30.0)
    msgs = []
    for i in range(3):
        core.offer(frame(5_000 + i), now_mono_ns=i * 40 * MS)
        f = core.take()
        assert f is not None
        msgs.append(core.message(f, b"jpeg%d" % i, pub_mono_ns=77 + i))
    assert [m.header.seq for m in msgs] == [0, 1, 2]
    assert [m.header.stamp_ns for m in msgs] == [5_000, 5_001, 5_002]
    assert [m.header.pub_mono_ns for m in msgs] == [77, 78, 79]
    assert msgs[0].header.source == "camera/front"
    assert (msgs[2].camera, msgs[2].width, msgs[2].height, msgs[2].jpeg) == (
        "front", 64, 48, b"jpeg2")
    # the integrity check every decoder applies (common/imaging.py)
    assert [m.crc32 for m in msgs] == [zlib.crc32(b"jpeg%d" % i) for i in range(3)]
    assert core.stats.published == 3


def test_decimated_frames_are_counted_and_never_reach_the_slot():
    core = CameraCore("front", 64, 48, fps=10.0)
    results = [core.offer(frame(i), now_mono_ns=i * 25 * MS) for i in range(8)]
    assert [i for i, r in enumerate(results) if r is Offer.PENDING] == [0, 3, 7]
    assert core.stats.decimated == 5
    assert core.stats.dropped == 2   # nothing took them: each admitted frame replaced the last


@pytest.mark.parametrize(
    ("image", "reason", "says"),
    [
        (np.zeros((48, 80, 3), np.uint8), "size_mismatch", "80x48 but the calibration is 64x48"),
        (np.zeros((48, 64), np.uint8), "bad_frame", "expected uint8 (H, W, 3)"),
        (np.zeros((48, 64, 3), np.float32), "bad_frame", "float32"),
    ],
)
def test_unusable_frames_are_rejected_and_counted(image, reason, says):
    core = CameraCore("front", 64, 48, fps=30.0)
    assert core.offer(Frame(image=image, stamp_ns=1), 0) is Offer.REJECTED
    assert core.take() is None
    assert core.stats.errors.get(reason) == 1
    assert says in core.last_rejection


def test_health_reports_each_state_and_a_stall():
    h = Health(stall_timeout_s=1.0)
    assert h.status(0) == (False, "opening source")
    h.streaming(0)
    assert h.status(500 * MS) == (True, "")
    assert h.status(1500 * MS) == (False, "no frame yet for 1.5 s")
    h.frame(2000 * MS)
    assert h.status(2500 * MS) == (True, "")
    healthy, status = h.status(3200 * MS, rejection="frame is 1x1")
    assert not healthy and status == "no frame for 1.2 s (frame is 1x1)"
    h.failed("read: unplugged", retry_in_s=2.0)
    assert h.reopens == 1
    assert h.status(3300 * MS) == (False, "source failed (read: unplugged); reopening in 2.0 s")
    h.failed("open: no device", retry_in_s=4.0)
    assert h.reopens == 1   # a failed reopen is not another reopen of a streaming source
    h.streaming(9000 * MS)
    assert h.status(9100 * MS) == (True, "")   # old frames do not make a fresh open stale
    h.ended()
    assert h.status(9200 * MS) == (False, "end of stream")


def test_backoff_doubles_to_its_cap_and_resets():
    b = Backoff(0.5, 3.0)
    assert [b.next_delay() for _ in range(5)] == [0.5, 1.0, 2.0, 3.0, 3.0]
    b.reset()
    assert b.next_delay() == 0.5


def test_camera_info_carries_the_calibration_and_counters_and_round_trips():
    cal = Calibration.load(CALIBRATION)
    core = CameraCore("front", cal.width, cal.height, fps=30.0)
    core.offer(frame(1, 10, 10), 0)   # wrong size: rejected
    core.stats.errors.add("source_error")
    info = camera_info(cal, "front", 30.0, "folder", core.stats, skipped_inputs=3,
                       healthy=False, status="no frame for 2.0 s", reopens=1,
                       header=Header(seq=0, source="camera/front", stamp_ns=1, pub_mono_ns=2))
    assert info.k == (615.0, 0.0, 424.0, 0.0, 615.0, 240.0, 0.0, 0.0, 1.0)
    assert info.dist == (0.0,) * 5
    np.testing.assert_allclose(np.reshape(info.r, (3, 3)), cal.r)
    np.testing.assert_allclose(info.t_m, cal.t)
    assert info.errors == {"size_mismatch": 1, "source_error": 1, "unreadable_input": 3}
    assert info.read_errors == 5
    assert (info.frames_captured, info.reopens, info.healthy) == (1, 1, False)
    assert decode(encode(info), CameraInfo) == info
    # What fusion does with it: rebuild the calibration from the message.
    back = Calibration.from_matrices(info.width, info.height, np.reshape(info.k, (3, 3)),
                                     np.array(info.dist), np.reshape(info.r, (3, 3)),
                                     np.array(info.t_m))
    np.testing.assert_allclose(back.project(np.array([[9.2, 1.0, 0.0]]))[0],
                               cal.project(np.array([[9.2, 1.0, 0.0]]))[0])


def test_a_rejection_reason_is_forgotten_once_a_good_frame_arrives():
    core = CameraCore("front", 64, 48, fps=30.0)
    core.offer(frame(1, w=80), 0)
    assert "80x48" in core.last_rejection
    core.offer(frame(2), 40 * MS)
    assert core.last_rejection == ""
