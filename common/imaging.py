"""The one JPEG path of the project: every tool decodes and encodes through here, so that
an edge-density threshold means the same everywhere.

Decoding uses simplejpeg in strict mode: a truncated or corrupt JPEG raises instead of
decoding into garbage pixels (OpenCV only prints a warning for mid-stream corruption).
Frames are decoded straight to grayscale (the gate's input); this differs from a colour
decode followed by cvtColor by a few grey levels, which is why there is only one path.
"""

import numpy as np
import simplejpeg


class ImageDecodeError(ValueError):
    """A payload that is not a complete, valid JPEG of the expected size."""


def decode_gray(jpeg: bytes | bytearray | memoryview, width: int = 0,
                height: int = 0) -> np.ndarray:
    """Decode to a 2-D uint8 grayscale array (a view, contiguous rows).

    When `width` and `height` are given, the decoded size must match them.
    Raises ImageDecodeError.
    """
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


def decode_bgr(jpeg: bytes | bytearray | memoryview) -> np.ndarray:
    """Decode to BGR for drawing (never for the gate). Raises ImageDecodeError."""
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
