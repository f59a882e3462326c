"""The grey frame a record's verifiers saw, rebuilt from its `FrameRef`, and the colour
frame shown to a labeller. Data-set images are read in place.

Images (data sets) are resized to the evaluation's pixel scale with INTER_AREA and,
with a JPEG quality, coded and decoded through common.imaging as the camera service
would publish them, so that a density means what it means in fusion.
"""

import hashlib
from pathlib import Path

import cv2
import numpy as np

from aeb_radar_camera.common.imaging import ImageDecodeError, decode_bgr, decode_gray, encode_jpeg
from aeb_radar_camera.common.messages import CompressedFrame, DecodeError, decode
from aeb_radar_camera.tools.eval.records import FrameRef, RoiRecord
from aeb_radar_camera.tools.recording.reader import Recording, RecordingError


class FrameLoadError(ValueError):
    """The frame of a record cannot be rebuilt; the message says why."""


def resized_size(width: int, height: int, scale: float) -> tuple[int, int]:
    return max(1, round(width * scale)), max(1, round(height * scale))


def content_digest(gray: np.ndarray) -> str:
    """The SHA-256 of a grey frame at its own size (its shape, then its pixels): the
    same picture gives the same digest wherever it is stored and under any name."""
    a = np.ascontiguousarray(gray, dtype=np.uint8)
    h = hashlib.sha256(f"{a.shape[0]}x{a.shape[1]}:".encode())
    h.update(a.tobytes())
    return h.hexdigest()


def read_image(path: str | Path) -> np.ndarray:
    """An image file decoded to BGR at its own size. Raises FrameLoadError."""
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise FrameLoadError(f"{path}: not an image OpenCV can read")
    return bgr


def source_digest(bgr: np.ndarray) -> str:
    """content_digest of a data-set image as read (before resampling and JPEG coding,
    so that the evaluation's pixel scale does not change what frame it is)."""
    return content_digest(cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY))


def load_image(path: str | Path, scale: float, jpeg_quality: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """(grey, BGR) of an image file at `scale`. Raises FrameLoadError."""
    return prepare_image(read_image(path), scale, jpeg_quality)


def prepare_image(bgr: np.ndarray, scale: float, jpeg_quality: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(grey, BGR) of a decoded image at `scale`, JPEG-coded as the camera would."""
    if scale != 1.0:
        bgr = cv2.resize(bgr, resized_size(bgr.shape[1], bgr.shape[0], scale),
                         interpolation=cv2.INTER_AREA)
    if jpeg_quality > 0:
        jpeg = encode_jpeg(bgr, jpeg_quality)
        return decode_gray(jpeg), np.ascontiguousarray(decode_bgr(jpeg))
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY), bgr


def _frame_message(ref: FrameRef) -> CompressedFrame:
    try:
        for m in Recording.open(Path(ref.path)).records([ref.topic], ref.log_time_ns,
                                                        ref.log_time_ns + 1):
            return decode(m.data, CompressedFrame)
    except (RecordingError, DecodeError) as exc:
        raise FrameLoadError(str(exc)) from exc
    raise FrameLoadError(f"{ref.path}: no message on {ref.topic} at {ref.log_time_ns}")


def _load(ref: FrameRef, colour: bool) -> np.ndarray:
    if ref.kind == "image":
        gray, bgr = load_image(ref.path, ref.scale, ref.jpeg_quality)
        return bgr if colour else gray
    if ref.kind == "mcap":
        msg = _frame_message(ref)
        try:
            return (np.ascontiguousarray(decode_bgr(msg.jpeg, msg.crc32)) if colour
                    else decode_gray(msg.jpeg, crc32=msg.crc32))
        except ImageDecodeError as exc:
            raise FrameLoadError(f"{ref.path}: {exc}") from exc
    raise FrameLoadError(f"no frame for a record of kind {ref.kind!r}")


def load_gray(ref: FrameRef) -> np.ndarray:
    """The grey frame the verifiers saw. Raises FrameLoadError."""
    return _load(ref, colour=False)


def load_bgr(ref: FrameRef) -> np.ndarray:
    """The frame in colour for people (never for verifiers). Raises FrameLoadError."""
    return _load(ref, colour=True)


def frame_digest(ref: FrameRef) -> str:
    """The content digest of a record's frame: a data-set image as read (source_digest),
    a recording's frame as decoded to grey (what fusion decodes). Raises FrameLoadError."""
    if ref.kind == "image":
        return source_digest(read_image(ref.path))
    if ref.kind == "mcap":
        return content_digest(_load(ref, colour=False))
    raise FrameLoadError(f"no frame for a record of kind {ref.kind!r}")


def record_digest(record: RoiRecord, cache: dict[FrameRef, str] | None = None) -> str:
    """The record's `frame_sha256`, or computed from its frame when the set was written
    without it (`cache`: frame -> digest, to decode each frame once). Raises
    FrameLoadError."""
    if record.frame_sha256:
        return record.frame_sha256
    if cache is not None and record.frame_ref in cache:
        return cache[record.frame_ref]
    digest = frame_digest(record.frame_ref)
    if cache is not None:
        cache[record.frame_ref] = digest
    return digest
