"""Inputs for the evaluation tests, generated here (never real data in the repository):

- a simulator-like recording in the project's MCAP layout: rendered frames of a box
  approaching, radar cycles with a track on it and a ghost track on nothing, CameraInfo,
  the ground truth on `sim/world` and optionally its depth;
- a KITTI object folder and a View-of-Delft folder with synthetic images, labels,
  calibration, lidar (and radar) points in the data sets' own conventions.
"""

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.depth_image import encode_depth, to_units
from aeb_radar_camera.common.imaging import encode_jpeg
from aeb_radar_camera.common.keys import CAMERA_DEPTH, CAMERA_INFO, CAMERA_JPEG, RADAR_TRACKS
from aeb_radar_camera.common.messages import CameraInfo, CompressedFrame, DepthFrame, Header
from aeb_radar_camera.tools.eval.depth import box_scene_depth
from aeb_radar_camera.tools.keys import SIM_WORLD
from aeb_radar_camera.tools.messages import ObjectKind, SimObject, SimWorld
from aeb_radar_camera.tools.recording.writer import RecordingWriter
from aeb_radar_camera.tools.sim.scenario import DEFAULT_SIZE
from aeb_radar_camera.tools.sim.scenes import Obstacle, Scene, render
from tests.fusion.helpers import CAL, T0, cycle, track

MS = 1_000_000
FRAME_NS = 33_333_333
RADAR_NS = 75 * MS
BOX_SPEED = 2.0
GHOST_XY = (9.0, 3.0)


def box_face_x(t_ns: int) -> float:
    """The box's face nearest the ego, in the radar frame, at wall time `t_ns`."""
    return 12.0 - BOX_SPEED * (t_ns - T0) / 1e9


def camera_info(cal: Calibration, stamp_ns: int) -> CameraInfo:
    return CameraInfo(header=Header(0, "camera/front", stamp_ns, 0), camera="front",
                      width=cal.width, height=cal.height, k=tuple(cal.k.ravel().tolist()),
                      dist=tuple(cal.dist.ravel().tolist()), r=tuple(cal.r.ravel().tolist()),
                      t_m=tuple(cal.t.ravel().tolist()), fps=30.0, source="synthetic",
                      frames_published=0, frames_dropped=0, read_errors=0, healthy=True,
                      status="")


def world(stamp_ns: int, seq: int) -> SimWorld:
    length, width, height = DEFAULT_SIZE[ObjectKind.BOX]
    x = box_face_x(stamp_ns) + length / 2
    box = SimObject(0, ObjectKind.BOX, x, 0.0, 0.0, length, width, height, -BOX_SPEED, 0.0)
    return SimWorld(header=Header(seq, "sim", stamp_ns, 0), scenario="test", run=1,
                    active=True, t_s=(stamp_ns - T0) / 1e9, ego_x_m=0.0, ego_speed_mps=0.0,
                    ego_accel_mps2=0.0, gap_m=None, ttc_s=None, objects=(box,), seed=3,
                    brightness=1.0, noise=2.0)


@dataclass
class SimRecording:
    path: Path
    frames: list[tuple[int, int, int]]       # (seq, stamp, log time), undecodable left out
    cycles: list[tuple[int, int]]            # (radar stamp, log time)


def box_depth(t_ns: int) -> np.ndarray:
    """The box of `world` at `t_ns` and the road as a depth image (box_scene_depth)."""
    length, width, height = DEFAULT_SIZE[ObjectKind.BOX]
    x = box_face_x(t_ns)
    return box_scene_depth(CAL, ((x, x + length, -width / 2, width / 2, 0.0, height),))


def write_sim_recording(path: Path, n_cycles: int = 8, corrupt_seqs: tuple[int, ...] = (),
                        vehicle: str = "ego", with_depth: bool = False,
                        depth_every: int = 1) -> SimRecording:
    """Frames at 30 fps (logged 5 ms after capture), radar cycles every 75 ms (logged
    2 ms after), the world at 50 Hz; with `with_depth` a DepthFrame (decimated 2) with
    every `depth_every`-th frame, logged 1 ms after it."""
    end = T0 + n_cycles * RADAR_NS + 40 * MS
    frames, cycles = [], []
    jpeg_topic = CAMERA_JPEG.key(vehicle, camera="front")
    with RecordingWriter(path) as w:
        w.write_message(CAMERA_INFO.key(vehicle, camera="front"), camera_info(CAL, T0), T0)
        seq, t = 0, T0
        while t < end:
            scene = Scene((Obstacle(box_face_x(t), 0.0, ObjectKind.BOX),), seed=3)
            jpeg = encode_jpeg(render(CAL, scene), 80)
            if seq in corrupt_seqs:
                jpeg = jpeg[: len(jpeg) // 3]
            else:
                frames.append((seq, t, t + 5 * MS))
            msg = CompressedFrame(header=Header(seq, "camera/front", t, 0), camera="front",
                                  width=CAL.width, height=CAL.height, jpeg=jpeg)
            w.write_message(jpeg_topic, msg, t + 5 * MS)
            if with_depth and seq % depth_every == 0:
                units = to_units(box_depth(t))[::2, ::2]
                w.write_message(CAMERA_DEPTH.key(vehicle, camera="front"),
                                DepthFrame(header=Header(seq, "camera/front", t, 0),
                                           camera="front", width=units.shape[1],
                                           height=units.shape[0], codec="zstd",
                                           data=encode_depth(units)), t + 6 * MS)
            seq += 1
            t += FRAME_NS
        for i, t in enumerate(range(T0, end, 20 * MS)):
            w.write_message(SIM_WORLD.key(vehicle), world(t, i), t + MS)
        for j in range(n_cycles):
            t = T0 + 20 * MS + j * RADAR_NS
            x = box_face_x(t)
            tracks = (track(1, x, 0.0, -BOX_SPEED, 0.0),
                      track(2, *GHOST_XY, 0.0, 0.0),
                      track(3, 40.0, 0.0, -BOX_SPEED, 0.0),          # beyond 25 m
                      track(4, 8.0, -1.0, 0.0, 0.0, confirmed=False))
            w.write_message(RADAR_TRACKS.key(vehicle, sensor="front"), cycle(*tracks, seq=j,
                                                                      stamp_ns=t), t + 2 * MS)
            cycles.append((t, t + 2 * MS))
    return SimRecording(path, frames, cycles)


# -- data sets --------------------------------------------------------------------------

# KITTI-like calibration: P2 with cam2's offset, a slight R0_rect, the usual Velodyne pose
# (x forward, 0.27 m behind and 0.08 m above the rectified camera).
KITTI_F = 721.5
KITTI_SIZE = (1242, 375)
KITTI_P2 = np.array([[KITTI_F, 0.0, 609.6, 44.86], [0.0, KITTI_F, 172.9, 0.2163],
                     [0.0, 0.0, 1.0, 0.002746]])
_ANG = math.radians(0.4)
KITTI_R0 = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(_ANG), -math.sin(_ANG)],
                     [0.0, math.sin(_ANG), math.cos(_ANG)]])
KITTI_TR = np.array([[0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, -0.08], [1.0, 0.0, 0.0, -0.27]])
CAM_HEIGHT = 1.65


@dataclass(frozen=True)
class LabelledBox:
    """An object in the rectified camera frame (KITTI's label convention)."""

    cls: str
    x: float                    # bottom centre
    z: float
    h: float
    w: float
    length: float
    ry: float = 0.0
    y: float = CAM_HEIGHT

    def corners_rect(self) -> np.ndarray:
        xs = np.array([1, 1, -1, -1, 1, 1, -1, -1]) * self.length / 2
        zs = np.array([1, -1, -1, 1, 1, -1, -1, 1]) * self.w / 2
        ys = np.array([0, 0, 0, 0, -1, -1, -1, -1]) * self.h
        c, s = math.cos(self.ry), math.sin(self.ry)
        return np.stack([c * xs + s * zs + self.x, ys + self.y, -s * xs + c * zs + self.z], 1)


def _project_rect(p2: np.ndarray, pts: np.ndarray) -> np.ndarray:
    uvw = np.c_[pts, np.ones(len(pts))] @ p2.T
    return uvw[:, :2] / uvw[:, 2:3]


def _bbox(p2: np.ndarray, box: LabelledBox, size: tuple[int, int]) -> tuple[float, ...]:
    uv = _project_rect(p2, box.corners_rect())
    return (max(0.0, uv[:, 0].min()), max(0.0, uv[:, 1].min()),
            min(size[0] - 1.0, uv[:, 0].max()), min(size[1] - 1.0, uv[:, 1].max()))


def textured_image(size: tuple[int, int], boxes: Sequence[tuple[float, ...]], seed: int
                   ) -> np.ndarray:
    """Smooth grey background with strongly textured object boxes."""
    w, h = size
    rng = np.random.default_rng(seed)
    img = np.full((h, w, 3), 110, np.uint8)
    img[: h // 3] = 190                                         # sky
    for x0, y0, x1, y1 in boxes:
        r0, r1, c0, c1 = int(y0), int(y1) + 1, int(x0), int(x1) + 1
        patch = rng.integers(0, 255, (r1 - r0, c1 - c0, 1), np.uint8)
        img[r0:r1, c0:c1] = np.repeat(patch, 3, axis=2)
    return img


def _ground_points(rng: np.random.Generator, lidar_height: float) -> np.ndarray:
    xs = rng.uniform(3.0, 30.0, 3000)
    ys = rng.uniform(-8.0, 8.0, 3000)
    return np.c_[xs, ys, np.full(3000, -lidar_height) + rng.normal(0, 0.02, 3000)]


def _surface_points(rng: np.random.Generator, corners_sensor: np.ndarray, z0: float,
                    z1: float, n: int) -> np.ndarray:
    """Points on the vertical faces of a footprint, between heights z0 and z1."""
    out = []
    for i in range(4):
        a, b = corners_sensor[i], corners_sensor[(i + 1) % 4]
        t = rng.uniform(0, 1, n)
        xy = a + (b - a) * t[:, None]
        out.append(np.c_[xy, rng.uniform(z0, z1, n)])
    return np.concatenate(out)


def velo_from_rect(pts: np.ndarray) -> np.ndarray:
    rot = KITTI_R0 @ KITTI_TR[:, :3]
    return (pts - KITTI_R0 @ KITTI_TR[:, 3]) @ rot


def _fmt(values: np.ndarray) -> str:
    return " ".join(f"{v:.12e}" for v in np.ravel(values))


KITTI_BOXES = (
    LabelledBox("Car", x=1.0, z=12.0, h=1.5, w=1.7, length=4.0),
    LabelledBox("Pedestrian", x=-3.0, z=8.0, h=1.75, w=0.6, length=0.5),
    LabelledBox("Car", x=2.0, z=40.0, h=1.5, w=1.7, length=4.0),      # beyond 25 m
    LabelledBox("Van", x=-6.0, z=15.0, h=2.2, w=2.0, length=5.0),     # not a class
)
# A wall of lidar structure 1.5 m high, at least 1 m from every box: a negative.
WALL_RECT = ((6.0, 6.3), (9.0, 14.0))        # x from .. to, z from .. to


def write_kitti(root: Path, n_frames: int = 2) -> Path:
    """A KITTI split folder `root/training` with `n_frames` identical-layout frames."""
    split = root / "training"
    for d in ("image_2", "label_2", "calib", "velodyne"):
        (split / d).mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(7)
    for i in range(n_frames):
        fid = f"{i:06d}"
        boxes2d = [_bbox(KITTI_P2, b, KITTI_SIZE) for b in KITTI_BOXES]
        cv2.imwrite(str(split / "image_2" / f"{fid}.png"),
                    textured_image(KITTI_SIZE, boxes2d[:2], seed=i))
        lines = []
        for b, bb in zip(KITTI_BOXES, boxes2d, strict=True):
            lines.append(f"{b.cls} 0.00 0 0.0 {bb[0]:.2f} {bb[1]:.2f} {bb[2]:.2f} {bb[3]:.2f} "
                         f"{b.h:.2f} {b.w:.2f} {b.length:.2f} {b.x:.2f} {b.y:.2f} {b.z:.2f} "
                         f"{b.ry:.2f}")
        lines.append("DontCare -1 -1 -10 900.0 150.0 950.0 180.0 -1 -1 -1 -1000 -1000 -1000 -10")
        (split / "label_2" / f"{fid}.txt").write_text("\n".join(lines) + "\n")
        (split / "calib" / f"{fid}.txt").write_text(
            f"P0: {_fmt(KITTI_P2)}\nP1: {_fmt(KITTI_P2)}\nP2: {_fmt(KITTI_P2)}\n"
            f"P3: {_fmt(KITTI_P2)}\nR0_rect: {_fmt(KITTI_R0)}\n"
            f"Tr_velo_to_cam: {_fmt(KITTI_TR)}\nTr_imu_to_velo: {_fmt(KITTI_TR)}\n")
        lidar_h = CAM_HEIGHT + 0.08
        pts = [_ground_points(rng, lidar_h)]
        for b in KITTI_BOXES[:2]:
            corners = velo_from_rect(b.corners_rect()[:4])[:, :2]
            pts.append(_surface_points(rng, corners, -lidar_h + 0.1, -lidar_h + b.h, 60))
        (x0, x1), (z0, z1) = WALL_RECT
        wall = np.array([[x0, CAM_HEIGHT, z0], [x1, CAM_HEIGHT, z0], [x1, CAM_HEIGHT, z1],
                         [x0, CAM_HEIGHT, z1]])
        pts.append(_surface_points(rng, velo_from_rect(wall)[:, :2], -lidar_h + 0.4,
                                   -lidar_h + 1.5, 80))
        cloud = np.concatenate(pts)
        np.c_[cloud, np.zeros(len(cloud))].astype(np.float32).tofile(
            split / "velodyne" / f"{fid}.bin")
    return split


# View-of-Delft: a camera pitched 5 degrees down, the lidar 1.5 m up; labels in the camera
# frame, rotation about the lidar's -z with VoD's quarter turn.
VOD_F = 1495.5
VOD_SIZE = (1936, 1216)
VOD_K = np.array([[VOD_F, 0.0, 961.3], [0.0, VOD_F, 624.9], [0.0, 0.0, 1.0]])
_P = math.radians(5.0)
# camera from lidar: optical axes (x right, y down, z forward) of a camera pitched down.
VOD_R = np.array([[0.0, -1.0, 0.0],
                  [-math.sin(_P), 0.0, -math.cos(_P)],
                  [math.cos(_P), 0.0, -math.sin(_P)]])
VOD_T = np.array([0.0, -0.2, 0.1])
VOD_LIDAR_HEIGHT = 1.5
# Radar (front bumper, 1.8 m ahead of the lidar, 1 m lower): camera from radar.
VOD_RADAR_OFFSET = np.array([1.8, 0.0, -1.0])      # radar origin in the lidar frame


@dataclass(frozen=True)
class VodObject:
    cls: str
    x: float                    # bottom centre in the lidar frame
    y: float
    h: float
    w: float
    length: float
    yaw: float = 0.0            # about lidar z


VOD_OBJECTS = (VodObject("Car", 14.0, 1.0, 1.5, 1.8, 4.2),
               VodObject("Cyclist", 9.0, -2.0, 1.7, 0.6, 1.8, 0.3))
VOD_CLUTTER_XY = (10.0, 4.0)          # a radar return on nothing


def _vod_corners(o: VodObject) -> np.ndarray:
    xs = np.array([1, 1, -1, -1]) * o.length / 2
    ys = np.array([1, -1, -1, 1]) * o.w / 2
    c, s = math.cos(o.yaw), math.sin(o.yaw)
    return np.stack([c * xs - s * ys + o.x, s * xs + c * ys + o.y], 1)


def write_vod(root: Path, n_frames: int = 1) -> Path:
    lidar = root / "lidar" / "training"
    radar = root / "radar" / "training"
    for d in ("image_2", "label_2", "calib", "velodyne"):
        (lidar / d).mkdir(parents=True, exist_ok=True)
    for d in ("calib", "velodyne"):
        (radar / d).mkdir(parents=True, exist_ok=True)
    p2 = np.c_[VOD_K, np.zeros(3)]
    tr = np.c_[VOD_R, VOD_T]
    tr_radar = np.c_[VOD_R, VOD_R @ VOD_RADAR_OFFSET + VOD_T]
    rng = np.random.default_rng(11)
    z_ground = -VOD_LIDAR_HEIGHT
    for i in range(n_frames):
        fid = f"{i:05d}"
        lines, boxes2d = [], []
        for o in VOD_OBJECTS:
            corners = _vod_corners(o)
            pts = np.concatenate([np.c_[corners, np.full(4, z_ground)],
                                  np.c_[corners, np.full(4, z_ground + o.h)]])
            cam = pts @ VOD_R.T + VOD_T
            uv = cam[:, :2] / cam[:, 2:3] * VOD_F + VOD_K[:2, 2]
            bb = (uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max())
            boxes2d.append(bb)
            loc = np.array([o.x, o.y, z_ground]) @ VOD_R.T + VOD_T
            rotation = -o.yaw - math.pi / 2
            lines.append(f"{o.cls} 0 0 0.0 {bb[0]:.2f} {bb[1]:.2f} {bb[2]:.2f} {bb[3]:.2f} "
                         f"{o.h} {o.w} {o.length} {loc[0]:.6f} {loc[1]:.6f} {loc[2]:.6f} "
                         f"{rotation:.6f} 1")
        cv2.imwrite(str(lidar / "image_2" / f"{fid}.jpg"),
                    textured_image(VOD_SIZE, boxes2d, seed=i))
        (lidar / "label_2" / f"{fid}.txt").write_text("\n".join(lines) + "\n")
        (lidar / "calib" / f"{fid}.txt").write_text(
            f"P0: {_fmt(p2)}\nP1: {_fmt(p2)}\nP2: {_fmt(p2)}\nP3: {_fmt(p2)}\n"
            f"R0_rect: {_fmt(np.eye(3))}\nTr_velo_to_cam: {_fmt(tr)}\nTr_imu_to_velo: \n")
        (radar / "calib" / f"{fid}.txt").write_text(
            f"P0: {_fmt(p2)}\nP1: {_fmt(p2)}\nP2: {_fmt(p2)}\nP3: {_fmt(p2)}\n"
            f"R0_rect: {_fmt(np.eye(3))}\nTr_velo_to_cam: {_fmt(tr_radar)}\nTr_imu_to_velo: \n")
        cloud = [_ground_points(rng, VOD_LIDAR_HEIGHT)]
        for o in VOD_OBJECTS:
            cloud.append(_surface_points(rng, _vod_corners(o), z_ground + 0.1,
                                         z_ground + o.h, 50))
        pts = np.concatenate(cloud)
        np.c_[pts, np.zeros(len(pts))].astype(np.float32).tofile(lidar / "velodyne" /
                                                                  f"{fid}.bin")
        # Radar points in the radar frame: one on the car, one on nothing.
        car = VOD_OBJECTS[0]
        on_car = np.array([car.x - car.length / 2, car.y, z_ground + 0.7]) - VOD_RADAR_OFFSET
        clutter = np.array([*VOD_CLUTTER_XY, z_ground + 0.3]) - VOD_RADAR_OFFSET
        rad = np.zeros((2, 7), np.float32)
        rad[:, :3] = np.stack([on_car, clutter])
        rad.tofile(radar / "velodyne" / f"{fid}.bin")
    return root
