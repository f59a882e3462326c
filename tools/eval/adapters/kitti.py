"""KITTI 3-D object format: `image_2/*.png`, `label_2/*.txt`, `calib/*.txt`,
`velodyne/*.bin` under one split folder (e.g. `training/`). Read in place, never copied
(KITTI is CC BY-NC-SA 3.0).

Labels: type, truncation, occlusion, alpha, 2-D box (x0 y0 x1 y1), height, width,
length, location (bottom centre, rectified camera frame: x right, y down, z forward) and
rotation_y about the camera's y axis. Calibration: P2 (the left colour camera after
rectification, P2 = K [I | K^-1 p]), R0_rect and Tr_velo_to_cam. The sensor frame is the
Velodyne's (x forward, y left, z up); objects are converted into it.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aeb_radar_camera.tools.eval.adapters.paper_rois import Box2D, Box3D, DatasetFrame, orthonormal

DONT_CARE = "DontCare"


class KittiFormatError(ValueError):
    """A file that does not follow the KITTI object format; the message names it."""


def read_calib(path: Path) -> dict[str, np.ndarray]:
    """The matrices of a calib file by name. Raises KittiFormatError, OSError."""
    out = {}
    for i, line in enumerate(path.read_text().splitlines(), 1):
        name, sep, values = line.partition(":")
        if not sep or not values.strip():
            continue
        try:
            out[name.strip()] = np.array([float(v) for v in values.split()])
        except ValueError as exc:
            raise KittiFormatError(f"{path}:{i}: {exc}") from exc
    return out


def camera_from_velodyne(calib: dict[str, np.ndarray], path: Path
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(K of image_2, R, t) with X_cam2 = R X_velo + t. Raises KittiFormatError."""
    try:
        p2 = calib["P2"].reshape(3, 4)
        r0 = calib.get("R0_rect", np.eye(3).ravel()).reshape(3, 3)
        tr = calib["Tr_velo_to_cam"].reshape(3, 4)
    except (KeyError, ValueError) as exc:
        raise KittiFormatError(f"{path}: needs P2 (12 values), Tr_velo_to_cam (12) and "
                               f"R0_rect (9): {exc}") from exc
    k = p2[:, :3]
    offset = np.linalg.solve(k, p2[:, 3])       # cam2's offset from the rectified cam0
    r = orthonormal(r0 @ tr[:, :3])
    t = r0 @ tr[:, 3] + offset
    return k, r, t


def rect_to_velodyne(points_rect: np.ndarray, calib: dict[str, np.ndarray]) -> np.ndarray:
    """(N, 3) rectified-camera points to the Velodyne frame."""
    r0 = calib.get("R0_rect", np.eye(3).ravel()).reshape(3, 3)
    tr = calib["Tr_velo_to_cam"].reshape(3, 4)
    rot = orthonormal(r0 @ tr[:, :3])
    return (np.asarray(points_rect) - r0 @ tr[:, 3]) @ rot


@dataclass(frozen=True)
class LabelRow:
    """One object line of a KITTI-format label file, as written."""

    obj_class: str
    bbox: Box2D
    h: float
    w: float
    length: float
    location: np.ndarray        # the camera frame
    rotation: float


def read_label_rows(path: Path) -> tuple[list[LabelRow], list[Box2D]]:
    """(object lines, DontCare regions) of a KITTI-format label file (VoD's has a score
    after the 15 fields). Raises KittiFormatError naming the line."""
    rows, dontcare = [], []
    for i, line in enumerate(path.read_text().splitlines(), 1):
        f = line.split()
        if not f:
            continue
        if len(f) < 15:
            raise KittiFormatError(f"{path}:{i}: expected 15 fields, got {len(f)}")
        try:
            bbox = (float(f[4]), float(f[5]), float(f[6]), float(f[7]))
            if f[0] == DONT_CARE:
                dontcare.append(bbox)
                continue
            rows.append(LabelRow(f[0], bbox, float(f[8]), float(f[9]), float(f[10]),
                                 np.array([float(v) for v in f[11:14]]), float(f[14])))
        except ValueError as exc:
            raise KittiFormatError(f"{path}:{i}: {exc}") from exc
    return rows, dontcare


def read_labels(path: Path, calib: dict[str, np.ndarray]) -> tuple[list[Box3D], list[Box2D]]:
    """(objects in the Velodyne frame, DontCare regions). Raises KittiFormatError."""
    rows, dontcare = read_label_rows(path)
    boxes = []
    for row in rows:
        # Bottom corners in the rectified camera frame (KITTI's devkit convention).
        xs = np.array([row.length, row.length, -row.length, -row.length]) / 2.0
        zs = np.array([row.w, -row.w, -row.w, row.w]) / 2.0
        c, s = np.cos(row.rotation), np.sin(row.rotation)
        x, y, z = row.location
        corners = np.stack([c * xs + s * zs + x, np.full(4, y), -s * xs + c * zs + z], 1)
        velo = rect_to_velodyne(corners, calib)
        boxes.append(Box3D(row.obj_class, velo[:, :2], float(velo[:, 2].mean()), row.h,
                           row.bbox))
    return boxes, dontcare


def read_velodyne(path: Path) -> np.ndarray:
    """(N, 3) points of a float32 x, y, z, reflectance file. Raises KittiFormatError."""
    raw = np.fromfile(path, dtype=np.float32)
    if raw.size % 4:
        raise KittiFormatError(f"{path}: {raw.size} floats is not a multiple of 4")
    return raw.reshape(-1, 4)[:, :3].astype(np.float64)


def image_size(path: Path) -> tuple[int, int]:
    """(width, height) from the PNG header (or by decoding other formats)."""
    with open(path, "rb") as f:
        head = f.read(24)
    if head[:8] == b"\x89PNG\r\n\x1a\n":
        return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise KittiFormatError(f"{path}: not an image OpenCV can read")
    return int(img.shape[1]), int(img.shape[0])


def frame_ids(root: Path) -> list[str]:
    """The frames of a split that have an image, a label and a calib file."""
    labels = {p.stem for p in (root / "label_2").glob("*.txt")}
    calibs = {p.stem for p in (root / "calib").glob("*.txt")}
    images = {p.stem for p in (root / "image_2").iterdir()} if (root / "image_2").is_dir() \
        else set()
    return sorted(labels & calibs & images)


def find_image(folder: Path, frame_id: str) -> Path:
    for ext in (".png", ".jpg", ".jpeg"):
        p = folder / f"{frame_id}{ext}"
        if p.is_file():
            return p
    raise KittiFormatError(f"{folder}: no image for frame {frame_id}")


def read_frame(root: Path, frame_id: str, dataset: str = "kitti",
               with_lidar: bool = True) -> DatasetFrame:
    """One frame of a KITTI split folder. Raises KittiFormatError, OSError."""
    calib_path = root / "calib" / f"{frame_id}.txt"
    calib = read_calib(calib_path)
    k, r, t = camera_from_velodyne(calib, calib_path)
    boxes, dontcare = read_labels(root / "label_2" / f"{frame_id}.txt", calib)
    image = find_image(root / "image_2", frame_id)
    width, height = image_size(image)
    velo = root / "velodyne" / f"{frame_id}.bin"
    lidar = read_velodyne(velo) if with_lidar and velo.is_file() else None
    return DatasetFrame(dataset, root.name, frame_id, image, k, width, height, r, t, boxes,
                        dontcare, lidar=lidar)


def looks_like(root: Path) -> bool:
    return all((root / d).is_dir() for d in ("image_2", "label_2", "calib"))
