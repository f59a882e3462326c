"""Data-set adapters: each reads one format into `DatasetFrame`s (paper_rois.py), from
which the paper's ROIs are built the same way for every data set.

- `kitti`: KITTI 3-D object format (image_2, label_2, calib, velodyne);
- `vod`: View-of-Delft (KITTI-like lidar folder, plus radar point clouds).
"""

from pathlib import Path

from aeb_radar_camera.tools.eval.adapters import kitti, vod
from aeb_radar_camera.tools.eval.adapters.paper_rois import DatasetFrame

KINDS = ("kitti", "vod")


def detect(root: Path) -> str | None:
    """The format of a folder, or None when it is neither."""
    if vod.looks_like(root):
        return "vod"
    if kitti.looks_like(root):
        return "kitti"
    return None


def frame_ids(kind: str, root: Path) -> list[str]:
    return vod.frame_ids(root) if kind == "vod" else kitti.frame_ids(root)


def read_frame(kind: str, root: Path, frame_id: str, with_lidar: bool = True
               ) -> DatasetFrame:
    """Raises kitti.KittiFormatError, OSError."""
    if kind == "vod":
        return vod.read_frame(root, frame_id, with_lidar)
    return kitti.read_frame(root, frame_id, with_lidar=with_lidar)
