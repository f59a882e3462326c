"""Image files of a folder, in natural sort order, paced at a fixed rate, optionally looped.

JPEG files are read through the project's strict JPEG path (common.imaging), so that a
truncated or corrupt JPEG is skipped instead of being delivered as half-grey garbage
(cv2.imread only warns about those); other formats go through cv2.imread. A file that
does not read is skipped, counted in `skipped` and logged (rate-limited).
"""

import logging
import re
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from aeb_radar_camera.common.clock import wall_ns
from aeb_radar_camera.common.imaging import ImageDecodeError, decode_bgr
from aeb_radar_camera.common.log import RateLimitedLog
from aeb_radar_camera.services.camera.source import (
    EndOfStream,
    Frame,
    FrameSource,
    Pacer,
    SourceError,
    as_bgr,
)

_log = logging.getLogger("camera.folder")
_DIGITS = re.compile(r"(\d+)")
_JPEG = (".jpg", ".jpeg")


def natural_key(name: str) -> tuple[tuple[int, int | str], ...]:
    """Sort key that orders "frame2" before "frame10" (digits compare as numbers)."""
    return tuple((0, int(part)) if part.isdigit() else (1, part.lower())
                 for part in _DIGITS.split(name) if part)


def list_images(folder: Path, extensions: tuple[str, ...]) -> list[Path]:
    """Image files directly in `folder` (case-insensitive extensions), in natural order.

    Raises SourceError when the folder cannot be listed.
    """
    wanted = {e.lower() for e in extensions}
    try:
        entries = [p for p in folder.iterdir() if p.suffix.lower() in wanted and p.is_file()]
    except OSError as exc:
        raise SourceError(f"cannot list image folder {folder}: {exc.strerror or exc}") from exc
    return sorted(entries, key=lambda p: natural_key(p.name))


def read_image(path: Path) -> np.ndarray | None:
    """A BGR uint8 image, or None when the file is unreadable or corrupt."""
    try:
        if path.suffix.lower() in _JPEG:
            return decode_bgr(path.read_bytes())
        image = cv2.imread(str(path), cv2.IMREAD_COLOR)
        return None if image is None else as_bgr(image)
    except (OSError, ImageDecodeError, ValueError):
        return None


class FolderSource(FrameSource):
    """Delivers the folder's images one per slot at `fps`; loops when `loop` is true.

    The list is re-read at every open; the position survives a reopen. A pass in which
    no file was readable raises SourceError (instead of spinning); reaching the end
    without `loop` raises EndOfStream.
    """

    kind = "folder"

    def __init__(self, path: str | Path, fps: float, loop: bool = True,
                 extensions: tuple[str, ...] = (".jpg", ".jpeg", ".png"),
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep,
                 wall_clock: Callable[[], int] = wall_ns) -> None:
        super().__init__()
        self.path = Path(path)
        self.loop = loop
        self.extensions = extensions
        self._pacer = Pacer(fps, clock, sleep)
        self._wall = wall_clock
        self._files: list[Path] = []
        self._index = 0
        self._read_in_pass = 0
        self._rl = RateLimitedLog(_log)

    def describe(self) -> str:
        return f"folder {self.path} ({len(self._files)} files, loop={self.loop})"

    @property
    def files(self) -> list[Path]:
        return list(self._files)

    def open(self) -> None:
        if not self.path.is_dir():
            raise SourceError(f"image folder {self.path} does not exist")
        self._files = list_images(self.path, self.extensions)
        if not self._files:
            raise SourceError(
                f"no image files ({', '.join(self.extensions)}) in {self.path}")
        self._pacer.reset()

    def read(self) -> Frame:
        while True:
            if self._index >= len(self._files):
                if not self.loop:
                    raise EndOfStream(f"end of folder {self.path}")
                if self._read_in_pass == 0:
                    raise SourceError(f"no readable image in {self.path} "
                                      f"({len(self._files)} files skipped)")
                self._index = 0
                self._read_in_pass = 0
            path = self._files[self._index]
            self._index += 1
            image = read_image(path)
            if image is None:
                self._skipped += 1
                self._rl.warning(f"unreadable:{self.path}", "unreadable_image_skipped",
                                 file=path, skipped=self._skipped)
                continue
            self._read_in_pass += 1
            self._pacer.wait()
            return Frame(image=image, stamp_ns=self._wall())
