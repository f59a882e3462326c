"""Frames: decoding on arrival (one path, strict), the ring, and the choice of frame."""

import logging
import threading

import numpy as np
import pytest

from aeb_radar_camera.common.imaging import decode_gray, encode_jpeg
from aeb_radar_camera.common.messages import CompressedFrame, Header, encode
from aeb_radar_camera.services.fusion.frames import (
    QUEUE_SIZE,
    RING_SIZE,
    DecodedFrame,
    FrameDecoder,
    FrameError,
    decode_frame,
    select_frame,
)
from tests.fusion.helpers import MS, T0, frame
from tests.support import wait_for

_IMAGE = np.tile(np.arange(848, dtype=np.uint8)[None, :], (480, 1))


def compressed(stamp_ns: int = T0, seq: int = 0, truncate: bool = False,
               width: int = 848, height: int = 480) -> bytes:
    jpeg = encode_jpeg(np.ascontiguousarray(_IMAGE[:height, :width]), 80)
    if truncate:
        jpeg = jpeg[: len(jpeg) // 2]
    return encode(CompressedFrame(header=Header(seq=seq, source="camera/front",
                                                stamp_ns=stamp_ns, pub_mono_ns=0),
                                  camera="front", width=width, height=height, jpeg=jpeg))


def decoder() -> FrameDecoder:
    return FrameDecoder(848, 480, logging.getLogger("test"))


def test_decoded_frames_use_the_one_decode_path():
    payload = compressed(seq=3)
    got = decode_frame(payload, 11, 848, 480)
    assert (got.seq, got.stamp_ns, got.rx_mono_ns) == (3, T0, 11)
    expected = decode_gray(encode_jpeg(_IMAGE, 80))
    assert np.array_equal(got.gray, expected)


@pytest.mark.parametrize(("payload", "reason"), [
    (b"\x93garbage", "message"),
    (compressed(truncate=True), "jpeg"),
    (compressed(width=640), "size"),
])
def test_unusable_frames_raise_with_a_reason(payload, reason):
    with pytest.raises(FrameError) as err:
        decode_frame(payload, 0, 848, 480)
    assert err.value.reason == reason


def test_decoder_counts_unusable_frames_by_reason_and_keeps_good_ones():
    dec = decoder()
    dec.decode_now(compressed(seq=1), 1)
    dec.decode_now(b"junk", 2)
    dec.decode_now(compressed(seq=2, truncate=True), 3)
    snap = dec.snapshot()
    assert [f.seq for f in snap.frames] == [1]
    assert snap.undecodable == 2
    assert dec.errors_by_reason == {"message": 1, "jpeg": 1}
    assert snap.last_error_rx_mono_ns == 3 and "undecodable JPEG" in snap.last_error


def test_ring_keeps_the_newest_frames():
    dec = decoder()
    for i in range(RING_SIZE + 2):
        dec.decode_now(compressed(stamp_ns=T0 + i * 33 * MS, seq=i), i)
    assert [f.seq for f in dec.snapshot().frames] == list(range(2, RING_SIZE + 2))


def test_worker_thread_decodes_submitted_frames_and_drops_the_oldest_when_behind(monkeypatch):
    assert QUEUE_SIZE == 2 and RING_SIZE >= 3
    dec = decoder()
    busy, gate = threading.Event(), threading.Event()
    original = dec.decode_now

    def slow(payload: bytes, rx: int) -> None:
        busy.set()
        gate.wait(30)
        original(payload, rx)

    monkeypatch.setattr(dec, "decode_now", slow)
    dec.start()
    try:
        dec.submit(compressed(seq=0), "k", 0)
        assert busy.wait(30)                     # the worker holds frame 0
        for i in range(1, 6):
            dec.submit(compressed(seq=i), "k", i)
        gate.set()
        wait_for(lambda: dec.snapshot().frames and dec.snapshot().frames[-1].seq == 5, 30,
                 what="newest frame decoded")
        snap = dec.snapshot()
        assert snap.received == 6
        # The worker took frame 0 before the gate; of 1..5 only the last two fit the queue.
        assert snap.dropped == 3
        assert [f.seq for f in snap.frames] == [0, 4, 5]
    finally:
        dec.stop()


def seq_of(selected: DecodedFrame | None) -> int | None:
    return None if selected is None else selected.seq


def test_nearest_frame_within_the_skew_is_selected():
    frames = (frame(T0 - 80 * MS, seq=1), frame(T0 - 20 * MS, seq=2), frame(T0 + 30 * MS, seq=3))
    assert seq_of(select_frame(frames, T0, 100 * MS, align=True)) == 2
    assert seq_of(select_frame(frames, T0 + 10 * MS, 100 * MS, align=True)) == 3
    assert select_frame(frames, T0 + 200 * MS, 100 * MS, align=True) is None
    assert select_frame((), T0, 100 * MS, align=True) is None


def test_without_alignment_the_newest_frame_is_used_if_within_the_skew():
    frames = (frame(T0 - 10 * MS, seq=1, rx_mono_ns=1), frame(T0 + 60 * MS, seq=2, rx_mono_ns=2))
    assert seq_of(select_frame(frames, T0, 100 * MS, align=False)) == 2
    assert select_frame(frames, T0 - 50 * MS, 100 * MS, align=False) is None


def test_a_decoder_bug_is_counted_and_the_next_frames_still_decode(monkeypatch):
    from aeb_radar_camera.services.fusion import frames

    dec = decoder()
    real = frames.decode_frame
    calls = []

    def buggy(payload: bytes, rx: int, width: int, height: int) -> DecodedFrame:
        calls.append(rx)
        if len(calls) == 1:
            raise ZeroDivisionError("a bug")
        return real(payload, rx, width, height)

    monkeypatch.setattr(frames, "decode_frame", buggy)
    dec.start()
    try:
        dec.submit(compressed(seq=0), "k", 1)
        wait_for(lambda: dec.snapshot().undecodable == 1, 30, what="the bug counted")
        dec.submit(compressed(seq=1), "k", 2)
        wait_for(lambda: dec.snapshot().frames, 30, what="the next frame decoded")
        assert [f.seq for f in dec.snapshot().frames] == [1]
        assert dec.errors_by_reason == {"decoder_error": 1}
        assert "ZeroDivisionError" in dec.snapshot().last_error
    finally:
        dec.stop()
