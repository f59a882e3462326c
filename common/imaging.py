"""The one JPEG path of the project: every tool decodes and encodes through here, so that
an edge-density threshold means the same everywhere.

Decoding uses simplejpeg in strict mode: a truncated or corrupt JPEG raises instead of
decoding into garbage pixels (OpenCV only prints a warning for mid-stream corruption).
Frames are decoded straight to grayscale (the gate's input); this differs from a colour
decode followed by cvtColor by a few grey levels, which is why there is only one path.

Strict mode does not catch a flipped bit inside the entropy-coded data (most such JPEGs
still decode, into wrong pixels): a frame's CRC-32 (`CompressedFrame.crc32`, made by
`jpeg_crc32`) is checked before decoding when it is given.
"""

import zlib

import numpy as np
import simplejpeg


class ImageDecodeError(ValueError):
    """A payload that is not a complete, valid JPEG of the expected size."""


class ImageCorruptError(ImageDecodeError):
    """JPEG bytes whose CRC-32 is not the one the camera sent with them."""


def jpeg_crc32(jpeg: bytes | bytearray | memoryview) -> int:
    """The integrity check a camera sends with its JPEG bytes (`CompressedFrame.crc32`)."""
    return zlib.crc32(jpeg)


def check_crc32(jpeg: bytes | bytearray | memoryview, crc32: int | None) -> None:
    """Raises ImageCorruptError unless `crc32` is None or the bytes' CRC-32."""
    if crc32 is not None and jpeg_crc32(jpeg) != crc32:
        raise ImageCorruptError(f"corrupt JPEG: CRC-32 {jpeg_crc32(jpeg):08x}, "
                                f"sent {crc32 & 0xFFFFFFFF:08x}")


def decode_gray(jpeg: bytes | bytearray | memoryview, width: int = 0,
                height: int = 0, crc32: int | None = None) -> np.ndarray:
    """Decode to a 2-D uint8 grayscale array (a view, contiguous rows).

    When `width` and `height` are given, the decoded size must match them; when `crc32`
    is given, the bytes must have it. Raises ImageDecodeError (ImageCorruptError for a
    CRC mismatch).
    """
    check_crc32(jpeg, crc32)
    try:
        img = simplejpeg.decode_jpeg(bytes(jpeg), colorspace="GRAY", strict=True)
    except (ValueError, RuntimeError) as exc:
        raise ImageDecodeError(f"undecodable JPEG: {exc}") from exc
    gray = img[:, :, 0]
    if width and height and gray.shape != (height, width):
        raise ImageDecodeError(
            f"JPEG is {gray.shape[1]}x{gray.shape[0]}, expected {width}x{height}"
        )
    return gray


def decode_bgr(jpeg: bytes | bytearray | memoryview, crc32: int | None = None) -> np.ndarray:
    """Decode to BGR for drawing (never for the gate); `crc32` as for `decode_gray`.
    Raises ImageDecodeError."""
    check_crc32(jpeg, crc32)
    try:
        return simplejpeg.decode_jpeg(bytes(jpeg), colorspace="BGR", strict=True)
    except (ValueError, RuntimeError) as exc:
        raise ImageDecodeError(f"undecodable JPEG: {exc}") from exc


def encode_jpeg(image: np.ndarray, quality: int = 80) -> bytes:
    """Encode a BGR (H, W, 3) or grayscale (H, W) uint8 image. Raises ValueError."""
    if image.dtype != np.uint8:
        raise ValueError(f"expected uint8 image, got {image.dtype}")
    if image.ndim == 2:
        return simplejpeg.encode_jpeg(
            np.ascontiguousarray(image[:, :, None]), quality=quality, colorspace="GRAY"
        )
    return simplejpeg.encode_jpeg(
        np.ascontiguousarray(image), quality=quality, colorspace="BGR", colorsubsampling="420"
    )
