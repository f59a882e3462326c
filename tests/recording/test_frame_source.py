"""The offline source of fusion's frames (`aeb rerun fusion`, `aeb eval` on recordings):
once every frame is read, its feed is what fusion's FrameDecoder holds after decoding the
same payloads; pixels are produced only when read, by whatever produced the frame."""

import contextlib
import logging
from collections.abc import Callable
from dataclasses import replace
from functools import partial

import numpy as np
import pytest

from aeb_radar_camera.common.imaging import encode_jpeg, jpeg_crc32
from aeb_radar_camera.common.messages import CompressedFrame, DecodeError, Header, encode
from aeb_radar_camera.services.fusion.frames import RING_SIZE, FrameDecoder, FrameError, FrameFeed
from aeb_radar_camera.tools.recording.frame_source import DECODED_KEPT, FrameSource
from tests.fusion.helpers import CAL, MS, T0
from tests.fusion.test_depth_check import car, render_depth
from tests.fusion.test_depth_fusion import depth_payload

W, H = CAL.width, CAL.height
PERIOD = 33 * MS


def picture(seq: int) -> np.ndarray:
    """A picture of its own per frame (the live decoder's frozen-camera check stays quiet)."""
    rng = np.random.default_rng(seq)
    return rng.integers(0, 255, (H, W), dtype=np.uint8)


def payload(seq: int, damage: str = "") -> bytes:
    """A frame's CompressedFrame; `damage`: corrupt (bytes not matching the CRC-32),
    jpeg (truncated), size (not the calibration's), garbage (no readable header)."""
    if damage == "garbage":
        return b"\x93garbage"
    jpeg = encode_jpeg(picture(seq), 80)
    crc: int | None = jpeg_crc32(jpeg)
    if damage == "corrupt":
        jpeg = jpeg[:-40] + bytes(40)
    elif damage == "jpeg":
        jpeg, crc = jpeg[: len(jpeg) // 2], None
    width = W // 2 if damage == "size" else W
    return encode(CompressedFrame(
        header=Header(seq=seq, source="camera/front", stamp_ns=T0 + seq * PERIOD,
                      pub_mono_ns=0),
        camera="front", width=width, height=H, jpeg=jpeg, crc32=crc))


DAMAGE = {2: "corrupt", 5: "jpeg", 6: "garbage", 8: "size", 9: "garbage"}
FRAMES = [(payload(seq, DAMAGE.get(seq, "")), T0 + seq * PERIOD + 5 * MS) for seq in range(10)]
DEPTH = {seq: depth_payload(render_depth(CAL, boxes=(car(8.0 + seq),)), T0 + seq * PERIOD)
         for seq in (3, 4, 7)}
DEPTH[0] = depth_payload(np.ones((H, W), np.float32), T0, decimation=3)    # unusable


def source_reading_everything() -> FrameSource:
    src = FrameSource({"front": (W, H)})
    for seq, (data, rx) in enumerate(FRAMES):
        if seq in DEPTH:
            src.add_depth("front", DEPTH[seq], rx)
        try:
            frame = src.add_recorded("front", data, rx)
        except DecodeError:
            continue
        with contextlib.suppress(FrameError):
            _ = frame.gray
    for f in src.window("front"):
        _ = None if f.undecodable else f.depth_m
    return src


def counters(feed: FrameFeed) -> FrameFeed:
    return replace(feed, frames=())


def test_once_every_frame_is_read_the_feed_is_the_live_decoders():
    live = FrameDecoder(W, H, logging.getLogger("test"), camera="front")
    for seq, (data, rx) in enumerate(FRAMES):
        if seq in DEPTH:
            live.decode_depth_now(DEPTH[seq])
        live.decode_now(data, rx)
    # decode_now is the decoder's worker; its counts of payloads received are submit's.
    expected = replace(live.snapshot(), received=len(FRAMES), depth_received=len(DEPTH))
    got = source_reading_everything().feed("front", FRAMES[-1][1])
    assert counters(got) == counters(expected)
    assert got.undecodable == len(DAMAGE) and got.corrupt == 1 and got.depth_undecodable == 1
    assert got.last_error.startswith("CompressedFrame")       # frame 9: no header
    assert [(f.seq, f.stamp_ns, f.rx_mono_ns) for f in got.frames] == [
        (f.seq, f.stamp_ns, f.rx_mono_ns) for f in expected.frames] == [
        (seq, T0 + seq * PERIOD, FRAMES[seq][1]) for seq in (1, 3, 4, 7)]
    for mine, theirs in zip(got.frames, expected.frames, strict=True):
        assert np.array_equal(mine.gray, theirs.gray)
        if mine.seq in (3, 4, 7):
            assert mine.depth_m is not None and theirs.depth_m is not None
            assert np.array_equal(mine.depth_m, theirs.depth_m)
        else:
            assert mine.depth_m is None and theirs.depth_m is None


def test_pixels_are_decoded_when_first_read_and_once():
    src = FrameSource({"front": (W, H)})
    for data, rx in FRAMES[:2]:
        src.add_recorded("front", data, rx)
    feed = src.feed("front", FRAMES[1][1])
    assert len(feed.frames) == 2 and src.decoded == 0
    newest = feed.frames[-1]
    first = newest.gray
    assert src.decoded == 1 and newest.gray is first and src.decoded == 1


def test_an_undecodable_frame_raises_when_read_is_counted_once_and_leaves_the_ring():
    src = FrameSource({"front": (W, H)})
    for data, rx in FRAMES[:3]:                  # frame 2 is corrupt
        src.add_recorded("front", data, rx)
    at = FRAMES[2][1]
    bad = src.feed("front", at).frames[-1]
    for _ in range(2):
        with pytest.raises(FrameError) as err:
            _ = bad.gray
        assert err.value.reason == "corrupt"
    feed = src.feed("front", at)
    assert [f.seq for f in feed.frames] == [0, 1]
    assert (feed.undecodable, feed.corrupt, src.decode_failed) == (1, 1, 1)
    assert feed.last_error_rx_mono_ns == at and "CRC-32" in feed.last_error


def test_the_feed_at_a_moment_holds_and_counts_only_what_was_received_by_then():
    src = FrameSource({"front": (W, H)})
    for data, rx in FRAMES[:8]:
        with contextlib.suppress(DecodeError):    # frame 6: counted, never a frame
            src.add_recorded("front", data, rx)
    at = FRAMES[3][1]
    feed = src.feed("front", at)
    assert [f.seq for f in feed.frames] == [0, 1, 2, 3]
    assert feed.received == 4 and feed.last_error == ""
    later = src.feed("front", FRAMES[7][1])
    assert len(later.frames) == RING_SIZE and [f.seq for f in later.frames] == [3, 4, 5, 7]
    assert later.received == 8 and later.last_error_rx_mono_ns == FRAMES[6][1]


def test_any_producer_of_pixels_feeds_fusion_the_same_way():
    made: list[int] = []

    def render(seq: int) -> Callable[[], np.ndarray]:
        def produce() -> np.ndarray:
            made.append(seq)
            if seq == 1:
                raise FrameError("render", "the renderer failed")
            return picture(seq)
        return produce

    src = FrameSource({"front": (W, H)})
    frames = [src.add("front", seq, T0 + seq * PERIOD, T0 + seq * PERIOD, render(seq))
              for seq in range(3)]
    assert made == []
    assert np.array_equal(frames[2].gray, picture(2)) and made == [2]
    with pytest.raises(FrameError):
        _ = frames[1].gray
    feed = src.feed("front", T0 + 2 * PERIOD)
    assert [f.seq for f in feed.frames] == [0, 2] and feed.undecodable == 1


def test_decoded_pixels_are_let_go_beyond_the_last_few_read():
    src = FrameSource({"front": (W, H)})
    frames = [src.add("front", seq, T0 + seq, T0 + seq, partial(picture, seq))
              for seq in range(DECODED_KEPT + 1)]
    for f in frames:
        _ = f.gray
    assert src.decoded == DECODED_KEPT + 1
    _ = frames[-1].gray                          # still kept
    assert src.decoded == DECODED_KEPT + 1
    assert np.array_equal(frames[0].gray, picture(0))   # let go: produced again
    assert src.decoded == DECODED_KEPT + 2


def test_a_depth_producer_is_read_on_demand_once_and_a_failure_counted_once():
    made: list[int] = []

    def depth(seq: int) -> Callable[[], np.ndarray]:
        def produce() -> np.ndarray:
            made.append(seq)
            if seq == 1:
                raise FrameError("depth_codec", "the depth did not decode")
            return np.full((H, W), float(seq), np.float32)
        return produce

    src = FrameSource({"front": (W, H)})
    frames = [src.add("front", seq, T0 + seq * PERIOD, T0 + seq * PERIOD,
                      partial(picture, seq), depth(seq)) for seq in range(3)]
    feed = src.feed("front", T0 + 2 * PERIOD)
    assert made == [] and feed.depth_received == 3 and feed.depth_undecodable == 0
    first = frames[2].depth_m
    assert first is not None and float(first[0, 0]) == 2.0
    assert frames[2].depth_m is first and made == [2] and src.depth_produced == 1
    assert frames[1].depth_m is None and frames[1].depth_m is None and made == [2, 1]
    assert src.feed("front", T0 + 2 * PERIOD).depth_undecodable == 1
    assert not frames[1].undecodable and src.decoded == 0    # its pixels are still fine


def test_a_frames_depth_is_there_once_received_unless_pinned():
    # live fusion pairs a depth with its frame only once the depth has arrived
    src = FrameSource({"front": (W, H)})
    data, rx = FRAMES[3]
    frame = src.add_recorded("front", data, rx)
    src.add_depth("front", DEPTH[3], rx + 2 * MS)        # just after the frame
    src.feed("front", rx + MS)
    assert frame.depth_m is None and not src.has_depth("front", frame.stamp_ns)
    src.feed("front", rx + 2 * MS)
    assert frame.depth_m is not None and src.has_depth("front", frame.stamp_ns)
    # the recorded output says the live instance had none: none, whenever it arrived
    src.feed("front", rx + 10 * MS, depth_pins={frame.stamp_ns: False})
    assert frame.depth_m is None
    # ... or had it, received before the recorder got it
    src.feed("front", rx + MS, depth_pins={frame.stamp_ns: True})
    assert frame.depth_m is not None
