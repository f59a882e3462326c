"""Depth on the wire: the DepthFrame message, its key and the lossless codecs."""

import numpy as np
import pytest

from aeb_radar_camera.common.depth_image import (
    CODECS,
    DepthDecodeError,
    decode_depth,
    encode_depth,
    to_metres,
    to_units,
)
from aeb_radar_camera.common.keys import CAMERA_DEPTH, CAMERA_JPEG, REGISTRY
from aeb_radar_camera.common.messages import DepthFrame, Header, decode, encode
from aeb_radar_camera.common.messages.schema import zenoh_encoding


def depth_units(h: int = 48, w: int = 64) -> np.ndarray:
    rng = np.random.default_rng(0)
    units = rng.integers(180, 25000, (h, w)).astype(np.uint16)
    units[rng.random((h, w)) < 0.1] = 0
    return units


@pytest.mark.parametrize("codec", CODECS)
def test_every_codec_is_lossless_and_checks_the_size(codec):
    units = depth_units()
    data = encode_depth(units, codec)
    back = decode_depth(data, codec, 64, 48)
    assert back.dtype == np.uint16 and np.array_equal(back, units)
    with pytest.raises(DepthDecodeError):
        decode_depth(data, codec, 32, 48)
    with pytest.raises(DepthDecodeError):
        decode_depth(data[: len(data) // 2], codec, 64, 48)
    with pytest.raises(DepthDecodeError):
        decode_depth(b"\x00junk", codec, 64, 48)
    # A decimated view (strided) codes like a copy.
    assert np.array_equal(decode_depth(encode_depth(units[::2, ::2], codec), codec, 32, 24),
                          units[::2, ::2])


def test_metres_round_to_millimetres_and_out_of_range_is_no_return():
    metres = np.array([[0.0, 1.2344, 65.535, 70.0], [-1.0, np.nan, np.inf, 0.0005]])
    units = to_units(metres)
    assert units.tolist() == [[0, 1234, 65535, 0], [0, 0, 0, 0]]
    assert to_metres(units)[0, 1] == pytest.approx(1.234)
    with pytest.raises(ValueError):
        to_units(np.zeros((2, 2, 2)))
    with pytest.raises(ValueError):
        encode_depth(units.astype(np.float32))
    with pytest.raises(ValueError):
        encode_depth(units, "jpeg")
    with pytest.raises(DepthDecodeError):
        decode_depth(b"", "jpeg", 4, 2)


def test_depth_frame_round_trips_on_its_own_key_beside_the_jpeg():
    units = depth_units()
    msg = DepthFrame(header=Header(3, "camera/front", 1_000, 2_000), camera="front", width=64,
                     height=48, codec="zstd", data=encode_depth(units, "zstd"))
    got = decode(encode(msg), DepthFrame)
    assert got == msg and got.units_m == 0.001
    assert np.array_equal(decode_depth(got.data, got.codec, got.width, got.height), units)
    assert REGISTRY["camera_depth"] is CAMERA_DEPTH
    assert CAMERA_DEPTH.key("ego", camera="front") == "aeb/ego/camera/front/depth"
    assert CAMERA_DEPTH.match("aeb/ego/camera/front/depth", "ego") == {"camera": "front"}
    assert CAMERA_JPEG.match("aeb/ego/camera/front/depth", "ego") is None
    assert zenoh_encoding(DepthFrame) == "application/msgpack;aeb.DepthFrame"
    assert CAMERA_DEPTH.qos == CAMERA_JPEG.qos
