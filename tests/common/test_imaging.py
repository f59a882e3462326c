import numpy as np
import pytest

from aeb_radar_camera.common.imaging import ImageDecodeError, decode_gray, encode_jpeg


def frame() -> bytes:
    rng = np.random.default_rng(1)
    img = np.clip(rng.normal(120, 40, (480, 848, 3)), 0, 255).astype(np.uint8)
    return encode_jpeg(img, 80)


def test_round_trip_to_grayscale():
    gray = decode_gray(frame(), 848, 480)
    assert gray.shape == (480, 848) and gray.dtype == np.uint8


@pytest.mark.parametrize("mangle", [
    lambda b: b[: len(b) // 2],                                  # truncated
    lambda b: b[:2000] + b"\x00" * 200 + b[2200:],               # corrupt in the middle
    lambda b: b"not a jpeg",
    lambda b: b"",
])
def test_corrupt_jpeg_raises(mangle):
    with pytest.raises(ImageDecodeError):
        decode_gray(mangle(frame()))


def test_wrong_size_raises():
    with pytest.raises(ImageDecodeError, match="expected 640x480"):
        decode_gray(frame(), 640, 480)
