"""View-of-Delft (VoD): KITTI-like, with 3+1D radar point clouds. Read in place, never
copied (VoD is for research use only).

Layout under the data set's root:

    lidar/training/{image_2/*.jpg, label_2/*.txt, calib/*.txt, velodyne/*.bin}
    radar/training/{calib/*.txt, velodyne/*.bin}

Lidar calib: P2 and Tr_velo_to_cam (camera from lidar). Radar calib: Tr_velo_to_cam is
camera from radar. Radar points: float32 x, y, z, RCS, v_r, v_r_compensated, time.
Labels: KITTI's 15 fields plus a score; the location is the box's bottom centre in the
camera frame and the rotation is about the lidar's -z axis with a quarter turn
(yaw_lidar = -(rotation + pi/2)), as in VoD's devkit. The sensor frame is the lidar's.
"""

from pathlib import Path

import numpy as np

from aeb_radar_camera.tools.eval.adapters.kitti import (
    KittiFormatError,
    find_image,
    image_size,
    read_calib,
    read_label_rows,
    read_velodyne,
)
from aeb_radar_camera.tools.eval.adapters.paper_rois import Box2D, Box3D, DatasetFrame, orthonormal

RADAR_FIELDS = 7
CLASSES = ("Car", "Pedestrian", "Cyclist")


def _camera_from(calib: dict[str, np.ndarray], path: Path) -> tuple[np.ndarray, np.ndarray]:
    try:
        tr = calib["Tr_velo_to_cam"].reshape(3, 4)
    except (KeyError, ValueError) as exc:
        raise KittiFormatError(f"{path}: needs Tr_velo_to_cam (12 values): {exc}") from exc
    return orthonormal(tr[:, :3]), tr[:, 3].copy()


def read_labels(path: Path, r: np.ndarray, t: np.ndarray) -> tuple[list[Box3D], list[Box2D]]:
    """Objects in the lidar frame and DontCare regions. Raises KittiFormatError."""
    rows, dontcare = read_label_rows(path)
    boxes = []
    for row in rows:
        centre = (row.location - t) @ r           # lidar frame: bottom centre
        yaw = -(row.rotation + np.pi / 2)
        c, s = np.cos(yaw), np.sin(yaw)
        xs = np.array([row.length, row.length, -row.length, -row.length]) / 2.0
        ys = np.array([row.w, -row.w, -row.w, row.w]) / 2.0
        corners = np.stack([c * xs - s * ys + centre[0], s * xs + c * ys + centre[1]], 1)
        boxes.append(Box3D(row.obj_class, corners, float(centre[2]), row.h, row.bbox))
    return boxes, dontcare


def read_radar(path: Path) -> np.ndarray:
    """(N, 3) radar points (x, y, z). Raises KittiFormatError."""
    raw = np.fromfile(path, dtype=np.float32)
    if raw.size % RADAR_FIELDS:
        raise KittiFormatError(f"{path}: {raw.size} floats is not a multiple of "
                               f"{RADAR_FIELDS}")
    return raw.reshape(-1, RADAR_FIELDS)[:, :3].astype(np.float64)


def frame_ids(root: Path) -> list[str]:
    lidar = root / "lidar" / "training"
    labels = {p.stem for p in (lidar / "label_2").glob("*.txt")}
    calibs = {p.stem for p in (lidar / "calib").glob("*.txt")}
    images = {p.stem for p in (lidar / "image_2").iterdir()} if (lidar / "image_2").is_dir() \
        else set()
    return sorted(labels & calibs & images)


def read_frame(root: Path, frame_id: str, with_lidar: bool = True) -> DatasetFrame:
    """One VoD frame, radar points in the lidar frame. Raises KittiFormatError, OSError."""
    lidar_dir = root / "lidar" / "training"
    radar_dir = root / "radar" / "training"
    calib_path = lidar_dir / "calib" / f"{frame_id}.txt"
    calib = read_calib(calib_path)
    try:
        k = calib["P2"].reshape(3, 4)[:, :3]
    except (KeyError, ValueError) as exc:
        raise KittiFormatError(f"{calib_path}: needs P2 (12 values): {exc}") from exc
    r, t = _camera_from(calib, calib_path)
    boxes, dontcare = read_labels(lidar_dir / "label_2" / f"{frame_id}.txt", r, t)
    image = find_image(lidar_dir / "image_2", frame_id)
    width, height = image_size(image)
    velo = lidar_dir / "velodyne" / f"{frame_id}.bin"
    lidar = read_velodyne(velo) if with_lidar and velo.is_file() else None
    radar = None
    radar_bin = radar_dir / "velodyne" / f"{frame_id}.bin"
    radar_calib = radar_dir / "calib" / f"{frame_id}.txt"
    if radar_bin.is_file() and radar_calib.is_file():
        rr, rt = _camera_from(read_calib(radar_calib), radar_calib)
        cam = read_radar(radar_bin) @ rr.T + rt
        radar = (cam - t) @ r                     # camera -> lidar frame
    return DatasetFrame("vod", "training", frame_id, image, k, width, height, r, t, boxes,
                        dontcare, lidar=lidar, radar=radar)


def looks_like(root: Path) -> bool:
    return (root / "lidar" / "training" / "label_2").is_dir()
