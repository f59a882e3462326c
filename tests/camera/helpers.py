"""Shared test material for the camera: image folders and config files."""

from pathlib import Path

import cv2

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.imaging import encode_jpeg
from aeb_radar_camera.common.resources import EXAMPLE_CALIBRATION
from aeb_radar_camera.tools.sim.moving_box import MovingBoxSource

CALIBRATION = str(EXAMPLE_CALIBRATION)
WIDTH, HEIGHT = 848, 480


def write_folder(folder: Path, n: int, width: int = WIDTH, height: int = HEIGHT,
                 corrupt: tuple[str, ...] = ()) -> list[Path]:
    """`n` JPEG frames named frame0.jpg .. frame<n-1>.jpg (box moved by 10 frames each),
    plus the named corrupt files: a truncated JPEG ("*.jpg") or bytes that are no image.
    Returns the good files in order."""
    folder.mkdir(parents=True, exist_ok=True)
    scene = MovingBoxSource(Calibration.load(CALIBRATION), 30.0, speed_mps=3.0)

    def image(n: int) -> bytes:
        return encode_jpeg(cv2.resize(scene.render(n), (width, height),
                                      interpolation=cv2.INTER_AREA), 80)

    good = []
    for i in range(n):
        path = folder / f"frame{i}.jpg"
        path.write_bytes(image(10 * i))
        good.append(path)
    for name in corrupt:
        whole = image(0)
        (folder / name).write_bytes(whole[: len(whole) // 2] if name.endswith(".jpg")
                                    else b"this is not an image")
    return good


def folder_config(path: Path, endpoint: str, folder: Path, fps: float = 30.0,
                  name: str = "front", extra: str = "") -> Path:
    path.write_text(f"""
[zenoh]
connect = ["{endpoint}"]

[camera]
name = "{name}"
calibration = "{CALIBRATION}"
fps = {fps}
stats_period_s = 0
{extra}

[camera.source]
kind = "folder"
path = "{folder}"
loop = true
""")
    return path
