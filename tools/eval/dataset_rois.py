"""ROIs from a labelled data set (KITTI, View-of-Delft), scored by every verifier:
objects as positives, background and sensor-point negatives (adapters/paper_rois.py),
the image resampled to the paper's focal length and JPEG-coded as the camera would, and
where the data has lidar a depth image aligned to that image (optionally with the D435's
noise, tools/eval/depth.py) for verifiers that use depth.
"""

import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from aeb_radar_camera.common.depth_error import D435Noise
from aeb_radar_camera.services.fusion.verifiers import Observation
from aeb_radar_camera.tools.eval.adapters import read_frame
from aeb_radar_camera.tools.eval.adapters.kitti import KittiFormatError
from aeb_radar_camera.tools.eval.adapters.paper_rois import (
    Candidate,
    PaperRoiSettings,
    background_candidates,
    ground_plane,
    object_candidates,
    point_candidates,
    scaled,
    standing_in_column,
)
from aeb_radar_camera.tools.eval.depth import project_depth
from aeb_radar_camera.tools.eval.frames import (
    FrameLoadError,
    prepare_image,
    read_image,
    source_digest,
)
from aeb_radar_camera.tools.eval.options import DEPTH_MODES
from aeb_radar_camera.tools.eval.records import (
    KIND_BACKGROUND_STANDING,
    KIND_LIDAR,
    KIND_RADAR,
    FrameRef,
    RoiRecord,
)
from aeb_radar_camera.tools.eval.scoring import Scorer, lighting


@dataclass(frozen=True)
class DatasetSettings:
    paper: PaperRoiSettings = field(default_factory=PaperRoiSettings)
    jpeg_quality: int = 80          # as the camera service publishes (0: no JPEG)
    depth: str = "lidar"            # none | lidar | d435 (lidar with the D435 model)
    noise: D435Noise = field(default_factory=D435Noise)
    timing: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        if self.depth not in DEPTH_MODES:
            raise ValueError(f"depth {self.depth!r}: expected one of {', '.join(DEPTH_MODES)}")


def _bump(counters: dict[str, int], key: str, n: int = 1) -> None:
    counters[key] = counters.get(key, 0) + n


def session_name(root: Path) -> str:
    return f"{root.parent.name}/{root.name}" if root.parent.name else root.name


def frame_seed(seed: int, frame_id: str) -> int:
    """A seed per frame, the same on every run and worker."""
    return seed * 1_000_003 + zlib.crc32(frame_id.encode())


def dataset_records(kind: str, root: Path, frame_ids: list[str], s: DatasetSettings,
                    scorer: Scorer, counters: dict[str, int], errors: list[str]
                    ) -> list[RoiRecord]:
    """The scored ROIs of `frame_ids`. A frame that cannot be read is counted and
    skipped (`errors` gets why), never fatal."""
    out: list[RoiRecord] = []
    session = session_name(root)
    p = s.paper
    for frame_id in frame_ids:
        try:
            frame = read_frame(kind, root, frame_id, with_lidar=True)
            sc = scaled(frame, p.focal_px)
            source = read_image(frame.image_path)
            digest = source_digest(source)
            gray, _ = prepare_image(source, sc.scale, s.jpeg_quality)
        except (KittiFormatError, FrameLoadError, OSError, ValueError) as exc:
            _bump(counters, "frame_unreadable")
            errors.append(f"{session}/{frame_id}: {exc}")
            continue
        if gray.shape != (sc.height, sc.width):
            _bump(counters, "frame_size")
            continue
        _bump(counters, "frames")
        rng = np.random.default_rng(frame_seed(s.seed, frame_id))
        positives = object_candidates(frame, sc, p)
        background = background_candidates(frame, sc, positives, p, rng)
        plane = ground_plane(frame.lidar, rng) if frame.lidar is not None else None
        if frame.lidar is not None and plane is not None:
            stands = standing_in_column(frame, sc, background, frame.lidar, plane, p)
            background = [replace(c, kind=KIND_BACKGROUND_STANDING) if st else c
                          for c, st in zip(background, stands, strict=True)]
        candidates: list[Candidate] = positives + background
        if frame.lidar is not None:
            if plane is None:
                _bump(counters, "no_ground_plane")
            candidates += point_candidates(frame, sc, frame.lidar, KIND_LIDAR, plane, p,
                                           p.structure_min_height_m,
                                           p.structure_max_height_m, p.cluster_cell_m,
                                           p.lidar_min_points)
        if frame.radar is not None:
            candidates += point_candidates(frame, sc, frame.radar, KIND_RADAR, plane, p,
                                           None, None, p.radar_cell_m, p.radar_min_points)
        for key, n in sc.counters.items():
            _bump(counters, key, n)
        depth = None
        if s.depth != "none" and frame.lidar is not None:
            depth = project_depth(frame.lidar @ frame.r.T + frame.t, sc.k, sc.width,
                                  sc.height)
            if s.depth == "d435":
                depth = s.noise.apply(depth, rng)
        light, median = lighting(gray)
        ref = FrameRef("image", str(frame.image_path), scale=sc.scale,
                       jpeg_quality=s.jpeg_quality)
        for n, c in enumerate(candidates):
            if depth is not None and c.calibration is not None:
                scorer.prepare(c.calibration)
            obs = Observation(gray, c.roi, c.column, c.range_m, depth, c.calibration, c.xy_m)
            scores = scorer.score(obs)
            frame_us = scorer.full_frame_us(gray) if s.timing and n == 0 else None
            out.append(RoiRecord(
                id=f"{session}:{frame_id}:{c.kind}:{c.index}", source=frame.dataset,
                session=session, frame=frame_id, t_ns=0, camera="image_2",
                image_w=sc.width, image_h=sc.height, roi=c.roi,
                column=c.column, range_m=c.range_m, kind=c.kind, frame_ref=ref,
                obj_class=c.obj_class, truth=c.truth, density=scorer.density(obs, scores),
                lighting=light, frame_median=median, has_depth=depth is not None,
                object_in_view=c.object_in_view,
                scores=scores, frame_canny_us=frame_us, frame_sha256=digest))
            _bump(counters, f"rois_{c.kind}")
    return out

