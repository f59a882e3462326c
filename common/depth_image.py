"""The one depth-image path: depth aligned to a colour frame, as published in
`DepthFrame` (common/messages/camera.py), encoded and decoded here and nowhere else.

On the wire depth is uint16 in `units_m` (1 mm, what the RealSense D400 reports: its
`z16` stream with depth units 0.001), 0 where there is no return: lossless for the
camera's own output. Two lossless codecs (benchmarks/bench_depth.py compares them):

- `zstd`: the raw little-endian pixels through Zstandard (level 1);
- `png`: 16-bit grey PNG through OpenCV (compression level 1), readable by any image tool.

Decoding checks the size and the pixel count; a payload that does not decode raises
DepthDecodeError (a ValueError), never returns a wrong-sized image.
"""

import cv2
import numpy as np
import zstandard

from aeb_radar_camera.common.messages.camera import DEPTH_CODECS as CODECS

DEPTH_UNITS_M = 0.001
MAX_UNITS = 65535
DEFAULT_CODEC = "zstd"
ZSTD_LEVEL = 1
PNG_LEVEL = 1

# One (de)compressor per process: creating one costs more than a small frame.
_ZSTD_C = zstandard.ZstdCompressor(level=ZSTD_LEVEL)
_ZSTD_D = zstandard.ZstdDecompressor()


class DepthDecodeError(ValueError):
    """A depth payload that is not a complete image of the expected size and codec."""


def to_units(depth_m: np.ndarray, units_m: float = DEPTH_UNITS_M) -> np.ndarray:
    """Metres (float, 0 = none) to uint16 units; beyond the range (or not finite) is no
    return (0). Raises ValueError on a non-2-D array."""
    if depth_m.ndim != 2:
        raise ValueError(f"expected a 2-D depth image, got shape {depth_m.shape}")
    units = np.rint(np.nan_to_num(depth_m, nan=0.0, posinf=0.0) / units_m)
    units[(units < 0) | (units > MAX_UNITS)] = 0
    return units.astype(np.uint16)


def to_metres(units: np.ndarray, units_m: float = DEPTH_UNITS_M) -> np.ndarray:
    """uint16 units to float32 metres (0 stays 0)."""
    return units.astype(np.float32) * np.float32(units_m)


def encode_depth(units: np.ndarray, codec: str = DEFAULT_CODEC) -> bytes:
    """A uint16 (H, W) depth image to bytes. Raises ValueError (dtype, shape, codec)."""
    if units.dtype != np.uint16 or units.ndim != 2:
        raise ValueError(f"expected 2-D uint16 depth, got {units.dtype} {units.shape}")
    units = np.ascontiguousarray(units)      # a decimated view has strides
    if codec == "zstd":
        return _ZSTD_C.compress(units.astype("<u2", copy=False).tobytes())
    if codec == "png":
        ok, buf = cv2.imencode(".png", units, [cv2.IMWRITE_PNG_COMPRESSION, PNG_LEVEL])
        if not ok:
            raise ValueError("PNG encoding failed")
        return buf.tobytes()
    raise ValueError(f"unknown depth codec {codec!r}; known: {', '.join(CODECS)}")


def decode_depth(data: bytes | bytearray | memoryview, codec: str, width: int,
                 height: int) -> np.ndarray:
    """Bytes to a uint16 (height, width) depth image. Raises DepthDecodeError."""
    if width <= 0 or height <= 0:
        raise DepthDecodeError(f"bad depth size {width}x{height}")
    if codec == "zstd":
        expected = width * height * 2
        try:
            raw = _ZSTD_D.decompress(bytes(data), max_output_size=expected)
        except zstandard.ZstdError as exc:
            raise DepthDecodeError(f"undecodable zstd depth: {exc}") from exc
        if len(raw) != expected:
            raise DepthDecodeError(f"zstd depth holds {len(raw)} bytes, expected "
                                   f"{expected} ({width}x{height} uint16)")
        return np.frombuffer(raw, dtype="<u2").reshape(height, width).astype(np.uint16,
                                                                            copy=False)
    if codec == "png":
        img = cv2.imdecode(np.frombuffer(bytes(data), np.uint8), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise DepthDecodeError("undecodable PNG depth")
        if img.dtype != np.uint16 or img.shape != (height, width):
            raise DepthDecodeError(f"PNG depth is {img.dtype} {img.shape}, expected uint16 "
                                   f"({height}, {width})")
        return img
    raise DepthDecodeError(f"unknown depth codec {codec!r}; known: {', '.join(CODECS)}")
