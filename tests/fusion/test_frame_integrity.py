"""JPEG integrity: a frame whose bytes lost a bit is rejected by its CRC-32 before it is
decoded (most such JPEGs still decode, into wrong pixels), and counted as corrupt."""

import logging
import random

import numpy as np
import pytest

from aeb_radar_camera.common.imaging import (
    ImageCorruptError,
    decode_bgr,
    decode_gray,
    encode_jpeg,
    jpeg_crc32,
)
from aeb_radar_camera.common.messages import CompressedFrame, Header, decode, encode
from aeb_radar_camera.services.fusion.frames import FrameDecoder, FrameError, decode_frame
from tests.fusion.helpers import T0

W, H = 320, 240
FLIPS = 300


def scene() -> np.ndarray:
    """A road-like picture with edges everywhere and some noise (JPEG data in every block)."""
    rng = np.random.default_rng(7)
    img = np.tile(np.linspace(40, 200, W, dtype=np.uint8)[None, :, None], (H, 1, 3))
    img[H // 2:, :, :] = 90
    img[100:180, 120:200, :] = 30
    return np.clip(img + rng.integers(0, 24, img.shape), 0, 255).astype(np.uint8)


JPEG = encode_jpeg(scene(), 80)


def flipped(jpeg: bytes, bit: int) -> bytes:
    data = bytearray(jpeg)
    data[bit // 8] ^= 1 << (bit % 8)
    return bytes(data)


def bits(n: int) -> list[int]:
    return random.Random(19).sample(range(len(JPEG) * 8), n)


def payload(jpeg: bytes, crc32: int | None) -> bytes:
    return encode(CompressedFrame(header=Header(seq=1, source="camera/front", stamp_ns=T0,
                                                pub_mono_ns=0),
                                  camera="front", width=W, height=H, jpeg=jpeg, crc32=crc32))


def test_the_intact_frame_passes_its_check_and_decodes():
    assert decode_frame(payload(JPEG, jpeg_crc32(JPEG)), 0, W, H).gray.shape == (H, W)


def test_300_single_bit_flips_are_all_rejected_as_corrupt():
    crc = jpeg_crc32(JPEG)
    without_check = 0
    for bit in bits(FLIPS):
        bad = flipped(JPEG, bit)
        with pytest.raises(FrameError) as err:
            decode_frame(payload(bad, crc), 0, W, H)
        assert err.value.reason == "corrupt"
        with pytest.raises(ImageCorruptError):
            decode_bgr(bad, crc)
        try:
            decode_gray(bad, W, H)
            without_check += 1
        except ValueError:
            pass
    # what the check is for: without it many of these decode (into wrong pixels)
    assert without_check > FLIPS // 10


def test_the_decoder_counts_corrupt_frames_apart_and_keeps_the_good_ones():
    d = FrameDecoder(W, H, logging.getLogger("test"))
    crc = jpeg_crc32(JPEG)
    for bit in bits(5):
        d.decode_now(payload(flipped(JPEG, bit), crc), 0)
    d.decode_now(payload(JPEG, crc), 1)
    feed = d.snapshot()
    assert (feed.corrupt, feed.undecodable, len(feed.frames)) == (5, 5, 1)
    assert "corrupt JPEG" in feed.last_error


def test_a_frame_from_a_publisher_without_the_field_still_decodes():
    old = encode(CompressedFrame(header=Header(seq=1, source="camera/front", stamp_ns=T0,
                                               pub_mono_ns=0),
                                 camera="front", width=W, height=H, jpeg=JPEG))
    assert decode(old, CompressedFrame).crc32 is None
    assert decode_frame(old, 0, W, H).gray.shape == (H, W)
