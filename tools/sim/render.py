"""The simulated camera, pure: 848x480 BGR frames of the simulated world, rendered with
the same calibration (K, distortion, radar-to-camera R and t) that fusion projects with.

A SIMULATION of the camera (the real path is the RealSense/OpenCV sources), and the
project's one scene renderer: the closed-loop simulator's camera, the moving-box demo
source and the test and benchmark scenes (tools/sim/scenes.py) all draw through it.

The road is a textured ground plane (asphalt, lane markings, shoulders, grass) mapped per
pixel by intersecting each pixel's ray with the ground, with coarser texture levels far
away so that distant texels do not alias into false edges, and a haze that blends the
ground into the sky at the horizon. With `roadside` (the closed loop's default) the
asphalt is worn (stones, cracks, patches), hedges, trees and house fronts line the road
at +-ROADSIDE_Y_M and a tree line with buildings stands BACKDROP_M ahead: what real
images put around an obstacle, so that background ROIs have the edge density of real
ones (docs/simulator.md). Without it (the still test scenes of tools/sim/scenes.py): the
smooth road under an open sky. Cars and boxes are textured 3-D boxes; pedestrians
and bicycles are camera-facing cut-outs; the radar's false targets are what they are: a
manhole cover flat on the road, a sign board on its gantry above the road, a low guard
rail on posts. Objects are drawn far to near, so nearer ones hide farther ones as a
camera would see them.

`render_rgbd` also returns the aligned depth image, from the same geometry: per pixel
the camera-frame depth Z in metres (float32, as the RealSense's aligned depth stream
reports it after scaling) of the surface the colour pixel shows, 0 where nothing
returns (the sky). A SIMULATION of a depth camera, without its noise.

At night (`headlights`), `CameraLook.brightness` is the ambient light and the ego's low
beams light the road ahead and, falling with the square of distance, the objects facing
it; `Light`s (street lamps, oncoming headlights) are saturated blobs with a glow, and a
lamp lights a pool of road below it: the conditions in which the paper's gate loses
precision.
"""

import ctypes
import ctypes.util
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.depth_image import to_units
from aeb_radar_camera.tools.messages import Lighting, ObjectKind
from aeb_radar_camera.tools.sim import sprites
from aeb_radar_camera.tools.sim.road import Road, RoadView
from aeb_radar_camera.tools.sim.scenario import CameraLook
from aeb_radar_camera.tools.sim.world import Body

MAX_GROUND_M = 250.0
HAZE_M = 120.0
ROADSIDE_Y_M = 9.5              # hedges and house fronts this far left and right
BACKDROP_M = 150.0              # the far tree line, this far ahead of the camera
BACKDROP_WIDTH_M = 400.0
BACKDROP_RES_M = 0.1
_GEOMETRY_ROWS = 40             # rows per band when building the roadside geometry
# Approaching a bend the road's view is built again every VIEW_STEP_M (the bend's shape a
# few cm off between; objects are drawn where they are): at 20 km/h every third frame.
VIEW_STEP_M = 0.5
WALL_ROW_STEP = 8               # rows between exact wall distances (interpolated between)
NEVER_M = 1e6                   # the wall distance of a ray that never meets one
BACKDROP_CLARITY = 0.8          # its contrast through the haze (a clear day)
_MIP_FACTORS = (1, 4, 16)        # texture levels: 2 cm, 8 cm, 32 cm per texel
_SHADE_REAR, _SHADE_SIDE, _SHADE_TOP = 1.0, 0.78, 1.12
_NOISE_BANK = 4
_FACES = ("rear", "front", "side", "top")     # a box's faces, in a fixed order
# Light relative to a clear day, times the look's brightness.
AMBIENT = {Lighting.DAY: 1.0, Lighting.DUSK: 0.35, Lighting.NIGHT: 0.12, Lighting.RAIN: 0.7}
# More sensor noise (grey levels) in poor light, added to the look's.
EXTRA_NOISE = {Lighting.DAY: 0.0, Lighting.DUSK: 1.0, Lighting.NIGHT: 1.5, Lighting.RAIN: 2.0}
RAIN_CONTRAST = 0.6             # the image keeps this much of its contrast in rain ...
RAIN_GREY = 150.0               # ... washed out towards this grey
RAIN_STREAKS = 400              # falling drops in a frame
# The low beams: a cone ahead (half-width 1.5 m at the lamps, widening by 0.25 m a metre)
BEAM_HALF_WIDTH_M = 1.5
BEAM_SPREAD = 0.25


@dataclass(frozen=True)
class _PixelRays:
    """Per pixel (float32 unless said): whether the ray meets the ground (bool), where
    (vehicle frame), how far horizontally, at what camera-frame depth; the ray's
    horizontal direction, its slope (rise per horizontal metre), 1 / its horizontal
    length (horizontal distance to camera-frame depth), its distance to the backdrop."""

    ground: np.ndarray
    gx: np.ndarray
    gy: np.ndarray
    gdist: np.ndarray
    gz: np.ndarray
    hx: np.ndarray
    hy: np.ndarray
    slope: np.ndarray
    inv_h: np.ndarray
    backdrop_t: np.ndarray
    clear: np.ndarray           # 1 - the haze over the ground at its distance


@dataclass(frozen=True)
class _Backdrop:
    """The far tree line where it is nearer than the ground: colour, alpha, depth (0
    where it is not opaque)."""

    colour: np.ndarray
    alpha: np.ndarray
    depth: np.ndarray
    rows: tuple[int, int]       # the rows it shows in


# (texture level, rows y0:y1, columns x0:x1, map x, map y, blend weight)
_WallLayer = tuple[int, int, int, int, int, np.ndarray, np.ndarray, np.ndarray]


@dataclass
class _Geometry:
    """One view of the road: per texture band of rows the ground's texture coordinates
    (stations relative to the view's), the ground's blend weight against the background
    (sky, backdrop), the walls' layers, the depth of the empty scene."""

    bands: list[tuple[int, int, int, np.ndarray, np.ndarray]]
    weight: np.ndarray
    weight_bg: np.ndarray
    walls: list[_WallLayer]
    background: np.ndarray
    depth: np.ndarray
    depth_mm: np.ndarray | None = None


@dataclass(frozen=True)
class Light:
    """A lamp or a headlight at a world-frame position, drawn saturated with a glow; a
    light higher than 3 m (a street lamp) also lights the road below it."""

    x_m: float
    y_m: float
    z_m: float
    radius_m: float = 0.15


def release_freed_memory() -> None:
    """Hand freed heap memory back to the OS (glibc only; a no-op elsewhere).

    Building the geometry allocates ~90 MB of short-lived float64 arrays; glibc keeps
    freed blocks of that size in its heap, so without this the camera process that hosts
    the simulation would stay ~35 MB larger for its whole life.
    """
    name = ctypes.util.find_library("c")
    if name:
        trim = getattr(ctypes.CDLL(name), "malloc_trim", None)
        if trim is not None:
            trim(0)


def _mip_levels(base: np.ndarray) -> list[np.ndarray]:
    """The texture at every level of _MIP_FACTORS (blurred, then shrunk)."""
    levels = []
    for f in _MIP_FACTORS:
        tex = base
        if f > 1:
            tex = cv2.resize(cv2.GaussianBlur(base, (0, 0), f * 0.6),
                             (base.shape[1] // f, base.shape[0] // f),
                             interpolation=cv2.INTER_AREA)
        levels.append(tex)
    return levels


class Renderer:
    """Renders frames for one calibration. Building it precomputes the per-pixel ground
    (and roadside) geometry of the straight road and the textures (one to two seconds);
    `render` then costs about 5 ms for the plain road, 8-10 ms with the roadside, 2 ms
    more with depth (CPU on a quiet core). On a bend the view's geometry is built again
    whenever the ego's place relative to the bend changes (approaching it), and kept
    while it does not (on the arc, the view is the same at every station)."""

    def __init__(self, calibration: Calibration, seed: int = 0,
                 look: CameraLook | None = None, roadside: bool = True,
                 lighting: Lighting = Lighting.DAY) -> None:
        self.cal = calibration
        self.look = look or CameraLook()
        self.lighting = lighting
        self.roadside = roadside
        self._depth: np.ndarray | None = None     # the depth image being rendered
        self._static_depth_mm: np.ndarray | None = None
        self.width, self.height = calibration.width, calibration.height
        self.cam_pos = -calibration.r.T @ calibration.t      # camera centre, ground frame
        self._rng = np.random.default_rng(seed)
        self._seed = seed
        self._night_xy: tuple[np.ndarray, np.ndarray] | None = None
        self._rays: _PixelRays | None = None
        self._band_rows: list[tuple[int, int, int]] | None = None
        self._bend: tuple[tuple[float, float], object, _Geometry] | None = None
        self._streaks: list[np.ndarray] = []
        self._build_straight()
        self._textures()
        self._sprites: dict[tuple[int, str, str], sprites.Sprite] = {}
        self._beams: tuple[tuple[float, int], np.ndarray] | None = None
        self._noise: list[tuple[np.ndarray, np.ndarray]] = []     # (H, W) uint8: up, down
        self._noise_bgr = np.empty((self.height, self.width, 3), np.uint8)
        self._frame = 0
        self._make_noise()
        release_freed_memory()

    def new_scene(self, seed: int) -> None:
        """Start a scene: the objects' textures and the sensor noise come from `seed`, so
        that a scene renders the same whatever was rendered before it."""
        self._seed = seed
        self._sprites.clear()
        self._streaks = []
        self._make_noise()

    def set_look(self, look: CameraLook, lighting: Lighting | None = None) -> None:
        """Change brightness and sensor noise, and the lighting (unchanged when None);
        cheap: the geometry and textures stay."""
        lighting = self.lighting if lighting is None else lighting
        if look != self.look or lighting is not self.lighting:
            self.look = look
            self.lighting = lighting
            self._make_noise()

    def _make_noise(self) -> None:
        """Sensor noise, the same on the three channels, added and subtracted with
        saturation: a few frames drawn once and used in turn, so that rendering keeps up
        with 30 fps. The bank holds one channel, spread to three into one scratch image
        per frame (~0.1 ms): a three-channel bank would hold 6 MB more.

        It is drawn again at every scene, in the camera's capture thread: the float
        draws stay one channel (a few MB) and are given back at once, or that thread's
        heap would keep ~40 MB for the process's life.
        """
        rng = np.random.default_rng((self._seed, 1))
        self._noise = []
        self._frame = 0
        sigma = self.look.noise + EXTRA_NOISE[self.lighting]
        for _ in range(_NOISE_BANK if sigma > 0 else 0):
            n = np.round(rng.normal(0, sigma, (self.height, self.width)))
            self._noise.append((np.clip(n, 0, 255).astype(np.uint8),
                                np.clip(-n, 0, 255).astype(np.uint8)))
            del n
        release_freed_memory()

    # -- geometry -----------------------------------------------------------------------

    def _ground_hits(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per pixel, float64: whether its ray meets the ground within MAX_GROUND_M, where
        (x, y in the vehicle frame, 0 where it does not), how far from the camera, and the
        ray itself in the vehicle frame ((H, W, 3)). Sets the rays' normalised image
        coordinates (`_norm`) and the ground's camera-frame depth (`_ground_z`)."""
        h, w = self.height, self.width
        u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        pix = np.stack([u, v], axis=-1).reshape(-1, 1, 2)
        norm = cv2.undistortPoints(pix, self.cal.k, self.cal.dist).reshape(h, w, 2)
        rays = np.concatenate([norm, np.ones((h, w, 1))], axis=2) @ self.cal.r  # R^T d
        dz = rays[..., 2]
        cz = self.cam_pos[2]
        hits = dz < -1e-6
        s = np.where(hits, -cz / np.where(hits, dz, -1.0), 0.0)
        gx = self.cam_pos[0] + s * rays[..., 0]
        gy = self.cam_pos[1] + s * rays[..., 1]
        dist = np.hypot(gx - self.cam_pos[0], gy - self.cam_pos[1])
        ground = hits & (dist < MAX_GROUND_M)
        # The rays are R^T (x_n, y_n, 1): the scale s along one is the camera-frame depth.
        self._norm = norm.astype(np.float32)
        self._ground_z = np.where(ground, s, 0.0).astype(np.float32)
        return ground, np.where(ground, gx, 0.0), np.where(ground, gy, 0.0), dist, rays

    def _ground_xy(self) -> tuple[np.ndarray, np.ndarray]:
        """Where each ground pixel is in the vehicle frame, float32 (the beams and lamp
        pools at night). Computed again on the first night frame rather than kept from the
        geometry: by day it would hold 3 MB for nothing."""
        if self._night_xy is None:
            _, gx, gy, _, _ = self._ground_hits()
            self._night_xy = (gx.astype(np.float32), gy.astype(np.float32))
            release_freed_memory()
        return self._night_xy

    def _pixel_rays(self) -> _PixelRays:
        """The per-pixel rays a view of the road is built from (float32). Built for the
        straight view at start and dropped; built again (and kept) when a scene first
        shows a bend."""
        if self._rays is None:
            ground, gx, gy, dist, rays = self._ground_hits()
            horizontal = np.hypot(rays[..., 0], rays[..., 1])
            hx = rays[..., 0] / horizontal
            hy = rays[..., 1] / horizontal
            ahead = hx > 1e-9
            backdrop_t = np.where(ahead, BACKDROP_M / np.where(ahead, hx, 1.0), np.inf)
            f32 = np.float32
            clear = np.exp(-np.where(ground, dist, MAX_GROUND_M) / HAZE_M)   # 1 - haze
            self._rays = _PixelRays(
                ground, gx.astype(f32), gy.astype(f32), dist.astype(f32), self._ground_z,
                hx.astype(f32), hy.astype(f32), (rays[..., 2] / horizontal).astype(f32),
                (1.0 / horizontal).astype(f32), backdrop_t.astype(f32), clear.astype(f32))
            del self._ground_z
        return self._rays

    def _build_straight(self) -> None:
        """The road ahead without a bend: the view every straight road and every frame
        far enough before a bend shows; its texture bands' rows serve every view."""
        rays = self._pixel_rays()
        self._sky = self._sky_image(rays)
        if self.roadside:
            self._backdrop = self._backdrop_layer(rays)
        self._straight = self._view_geometry(Road(), 0.0, 0.0)
        self._rays = None
        release_freed_memory()

    def _rows_by_level(self, visible: np.ndarray, gx: np.ndarray) -> None:
        """The texture level of each image row with ground, from the row's largest texel
        footprint where the ground shows (on a level road the footprint grows row by row
        towards the horizon), as bands of rows of one level."""
        step = np.abs(np.diff(gx, axis=0, append=gx[-1:])) / sprites.ROAD_RES_M
        step = np.where(visible, step, 0.0).max(axis=1)
        row_level = np.where(step > 10.0, 2, np.where(step > 2.5, 1, 0))
        ground_rows = np.nonzero(visible.any(axis=1))[0]
        self._band_rows = []
        if len(ground_rows):
            r = int(ground_rows[0])
            last = int(ground_rows[-1]) + 1
            while r < last:
                lv = int(row_level[r])
                r_end = r + 1
                while r_end < last and int(row_level[r_end]) == lv:
                    r_end += 1
                self._band_rows.append((lv, r, r_end))
                r = r_end

    def _sky_image(self, rays: _PixelRays) -> np.ndarray:
        """The sky's gradient, the haze colour below the horizon."""
        elev = np.degrees(np.arctan(rays.slope))
        t = np.clip(elev / 35.0, 0.0, 1.0)[..., None]
        top = np.array([215, 170, 120], np.float32)
        return (sprites.HAZE_BGR * (1 - t) + top * t).round().astype(np.uint8)

    def _backdrop_layer(self, rays: _PixelRays) -> _Backdrop:
        """The tree line and buildings BACKDROP_M ahead where nearer than the ground: per
        pixel colour, alpha (through the haze) and depth. It stands still relative to the
        ego, like a far skyline (also through a bend)."""
        cam = self.cam_pos
        h, w = self.height, self.width
        tex = sprites.backdrop_texture(np.random.default_rng((self._seed, 7)),
                                       BACKDROP_WIDTH_M, BACKDROP_RES_M)
        th, tw = tex.shape[:2]
        colour = np.zeros((h, w, 3), np.uint8)
        alpha = np.zeros((h, w), np.float32)
        depth = np.zeros((h, w), np.float32)
        for r0 in range(0, h, _GEOMETRY_ROWS):
            r1 = min(r0 + _GEOMETRY_ROWS, h)
            tb = rays.backdrop_t[r0:r1]
            zb = cam[2] + tb * rays.slope[r0:r1]
            col = (BACKDROP_WIDTH_M / 2 - (cam[1] + tb * rays.hy[r0:r1])) / BACKDROP_RES_M
            row = (sprites.BACKDROP_HEIGHT_M - zb) / BACKDROP_RES_M
            ground_t = np.where(rays.ground[r0:r1], rays.gdist[r0:r1], np.inf)
            inside = (tb < ground_t) & (col >= 0) & (col < tw) & (row >= 0) & (row < th)
            sampled = cv2.remap(tex, np.where(inside, col, -1).astype(np.float32),
                                np.where(inside, row, -1).astype(np.float32),
                                cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                                borderValue=(0, 0, 0, 0))
            a = np.where(inside, sampled[..., 3] / np.float32(255.0), 0.0)
            opaque = a > 0.5
            alpha[r0:r1] = np.where(opaque, 1.0, a)
            colour[r0:r1] = sampled[..., :3]
            depth[r0:r1] = np.where(opaque, tb * rays.inv_h[r0:r1], 0.0)
        shown = np.flatnonzero(alpha.any(axis=1))
        rows = (int(shown[0]), int(shown[-1]) + 1) if len(shown) else (0, 0)
        return _Backdrop(colour, alpha, depth, rows)

    def _view_key(self, view: RoadView | None) -> tuple[float, float] | None:
        """What the road looks like from the ego, rounded: None for the straight view,
        else (distance to the bend in VIEW_STEP_M, 0 once in it; lateral offset)."""
        if view is None:
            return None
        road, d = view.road, round(view.d_m / 0.02) * 0.02
        ahead = road.s0 - view.s_m
        if (road.straight or ahead >= MAX_GROUND_M) and d == 0.0:
            return None
        return (round(max(ahead, 0.0) / VIEW_STEP_M) * VIEW_STEP_M, d)

    def _geometry(self, view: RoadView | None) -> _Geometry:
        key = self._view_key(view)
        if key is None or view is None:
            return self._straight
        cached = self._bend
        if cached is None or cached[0] != key or cached[1] is not view.road.geometry:
            road = view.road
            s_c = road.s0 - key[0]
            self._bend = (key, road.geometry, self._view_geometry(road, s_c, key[1]))
            cached = self._bend
        return cached[2]

    def _view_geometry(self, road: Road, s_c: float, d_c: float) -> _Geometry:
        """Texture coordinates, blend weights, walls and depth of every pixel with the
        ego's radar at station `s_c`, offset `d_c` of `road`: the ground (its texture
        along the lane centre, so markings follow a bend), the hedges and house fronts
        at ROADSIDE_Y_M either side of it (the first wall each pixel's ray meets on its
        way out of the corridor between them: straight walls, or circles about the
        bend's centre), the backdrop. Texture rows are stations relative to `s_c`. Built a
        band of rows at a time: whole-image temporaries would raise the camera process's
        peak memory by tens of MB."""
        rays = self._pixel_rays()
        cam = self.cam_pos
        h, w = self.height, self.width
        pose = road.pose_at(s_c, d_c)
        c, s = math.cos(pose.heading_rad), math.sin(pose.heading_rad)
        ox, oy = (float(v) for v in pose.to_world(np.array([[cam[0], cam[1]]]))[0])
        col0 = np.zeros((h, w), np.float32)
        row0 = np.zeros((h, w), np.float32)
        wall = np.zeros((h, w), bool)
        level = np.zeros((h, w), np.uint8)
        wx = np.zeros((h, w), np.float32)        # wall texture: along the road
        wz = np.zeros((h, w), np.float32)        # ... and up
        wt = np.zeros((h, w), np.float32)        # horizontal distance to the wall
        left = np.zeros((h, w), bool)
        depth = np.zeros((h, w), np.float32)
        visible = np.zeros((h, w), bool)
        if self.roadside:
            wall_t, wall_s, wall_d = self._walls_seen(road, ox, oy, c, s, rays)
        for r0 in range(0, h, _GEOMETRY_ROWS):
            r1 = min(r0 + _GEOMETRY_ROWS, h)
            ground = rays.ground[r0:r1]
            if ground.any():
                gx, gy = rays.gx[r0:r1], rays.gy[r0:r1]
                sg, dg = road.to_road(pose.x_m + c * gx - s * gy, pose.y_m + s * gx + c * gy)
                col0[r0:r1] = (sprites.ROAD_HALF_WIDTH_M - dg) / sprites.ROAD_RES_M
                row0[r0:r1] = (sg - s_c) / sprites.ROAD_RES_M
            gz = np.where(ground, rays.gz[r0:r1], 0.0)
            if self.roadside:
                t = wall_t[r0:r1]
                z = cam[2] + t * rays.slope[r0:r1]
                hit = (z >= 0) & (z <= sprites.SCENERY_HEIGHT_M) & (
                    t * rays.hx[r0:r1] < MAX_GROUND_M)
                zw = np.where(hit, t * rays.inv_h[r0:r1], 0.0)
                bz = self._backdrop.depth[r0:r1]
                behind = (bz > 0) & (~hit | (bz < zw))        # the backdrop hides it
                hit &= ~behind
                footprint = zw / self.cal.k[0, 0] / sprites.SCENERY_RES_M  # texels a pixel
                wall[r0:r1], wz[r0:r1], wt[r0:r1] = hit, z, t
                wx[r0:r1] = wall_s[r0:r1] - s_c
                left[r0:r1] = wall_d[r0:r1] > 0
                level[r0:r1] = np.where(footprint > 6.0, 2, np.where(footprint > 1.5, 1, 0))
                ground = ground & ~hit & ~behind
                depth[r0:r1] = np.where(behind, bz, np.where(hit, zw, gz))
            else:
                depth[r0:r1] = gz
            visible[r0:r1] = ground
        if self._band_rows is None:         # the straight view's rows serve every view
            self._rows_by_level(visible, rays.gx)
        assert self._band_rows is not None
        bands = [(lv, r0, r1, np.ascontiguousarray(col0[r0:r1] / _MIP_FACTORS[lv]),
                  np.ascontiguousarray(row0[r0:r1] / _MIP_FACTORS[lv]))
                 for lv, r0, r1 in self._band_rows]
        del col0, row0
        # out = road * weight + background * (1 - weight): haze over distant ground.
        weight = np.where(visible, rays.clear, np.float32(0.0))
        background = self._sky
        if self.roadside:
            background = self._sky.copy()
            b0, b1 = self._backdrop.rows
            a = np.where(wall[b0:b1], np.float32(0.0),
                         self._backdrop.alpha[b0:b1] * np.float32(BACKDROP_CLARITY))
            background[b0:b1] = cv2.blendLinear(self._backdrop.colour[b0:b1],
                                                self._sky[b0:b1], a, 1.0 - a)
            del a
        walls = self._wall_layers(wall, level, left, wx, wz, wt) if self.roadside else []
        return _Geometry(bands, weight, (1.0 - weight).astype(np.float32), walls, background,
                         depth)

    def _walls_seen(self, road: Road, ox: float, oy: float, c: float, s: float,
                    rays: _PixelRays) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per pixel the horizontal distance to the wall its ray meets (NEVER_M where
        none) and the station and lateral offset of that point. A pixel's horizontal
        direction changes little down an image column, so these are found on every
        WALL_ROW_STEP-th row and interpolated between (at a fraction of the cost)."""
        h = self.height
        rows = np.arange(0, h + WALL_ROW_STEP - 1, WALL_ROW_STEP).clip(max=h - 1)
        hx, hy = rays.hx[rows], rays.hy[rows]
        dwx, dwy = c * hx - s * hy, s * hx + c * hy
        t = self._wall_distance(road, ox, oy, dwx, dwy)
        seen = np.isfinite(t)
        t = np.where(seen, t, NEVER_M).astype(np.float32)
        ws = np.zeros_like(t)
        wd = np.zeros_like(t)
        ws[seen], wd[seen] = road.to_road(ox + t[seen] * dwx[seen], oy + t[seen] * dwy[seen])
        y = np.arange(h)
        i0 = np.minimum(y // WALL_ROW_STEP, len(rows) - 2)
        f = ((y - rows[i0]) / np.maximum(rows[i0 + 1] - rows[i0], 1)).astype(np.float32)[:, None]
        t, ws, wd = (a[i0] * (1 - f) + a[i0 + 1] * f for a in (t, ws, wd))
        return t, ws, wd

    @staticmethod
    def _wall_distance(road: Road, ox: float, oy: float, dwx: np.ndarray, dwy: np.ndarray
                       ) -> np.ndarray:
        """Horizontal distance along each ray (world direction dwx, dwy from the camera
        at ox, oy) to where it leaves the corridor between the walls: the straight walls
        before the bend, the circles about its centre after it; inf where never."""
        side = np.where(dwy >= 0, ROADSIDE_Y_M, -ROADSIDE_Y_M)
        steep = np.abs(dwy) > 1e-9
        t = np.where(steep, (side - oy) / np.where(steep, dwy, 1.0), np.inf)
        t = np.where(t > 0, t, np.inf)
        if road.straight:
            return t
        r = road.radius
        assert r is not None
        t = np.where(ox + t * dwx < road.s0, t, np.inf)
        relx, rely = ox - road.s0, oy - r
        b = dwx * relx + dwy * rely
        q = relx * relx + rely * rely
        for radius, sign in ((abs(r) + ROADSIDE_Y_M, 1.0), (abs(r) - ROADSIDE_Y_M, -1.0)):
            disc = b * b - (q - radius * radius)
            tc = -b + sign * np.sqrt(np.maximum(disc, 0.0))
            ok = (disc >= 0) & (tc > 0) & (ox + tc * dwx >= road.s0)
            t = np.where(ok & (tc < t), tc, t)
        return t

    def _wall_layers(self, wall: np.ndarray, level: np.ndarray, left: np.ndarray,
                     wx: np.ndarray, wz: np.ndarray, wt: np.ndarray) -> list[_WallLayer]:
        """The walls' texture coordinates (rows along the road, columns up) at their
        texture level, in a box per level and side; the haze from the distance."""
        layers: list[_WallLayer] = []
        rows_any = np.flatnonzero(wall.any(axis=1))
        if not len(rows_any):
            return layers
        top, bottom = int(rows_any[0]), int(rows_any[-1]) + 1     # the walls' rows only
        for (lv, f), on_left in itertools.product(enumerate(_MIP_FACTORS), (True, False)):
            mask = wall[top:bottom] & (level[top:bottom] == lv) & (left[top:bottom] == on_left)
            rows_i = np.flatnonzero(mask.any(axis=1))
            if not len(rows_i):
                continue
            cols_i = np.flatnonzero(mask.any(axis=0))
            y0, y1 = top + int(rows_i[0]), top + int(rows_i[-1]) + 1
            x0, x1 = int(cols_i[0]), int(cols_i[-1]) + 1
            m = mask[y0 - top:y1 - top, x0:x1]
            mx = wz[y0:y1, x0:x1] / np.float32(sprites.SCENERY_RES_M * f)
            my = wx[y0:y1, x0:x1] / np.float32(sprites.SCENERY_RES_M * f)
            fog = np.exp(-wt[y0:y1, x0:x1] / HAZE_M)
            weight = np.where(m, fog, 0.0).astype(np.float32)
            layers.append((lv, y0, y1, x0, x1, mx, my, weight))
        return layers

    def _textures(self) -> None:
        base = sprites.road_texture(self._rng)
        if self.roadside:
            sprites.road_wear(self._rng, base)
        self._tex = _mip_levels(base)
        self._wall_tex = (_mip_levels(sprites.roadside_texture(self._rng)) if self.roadside
                          else [])

    @property
    def static_depth(self) -> np.ndarray:
        """(H, W) float32 depth of the empty straight road and its roadside."""
        return self._straight.depth

    # -- per frame ------------------------------------------------------------------------

    def _road(self, ego_s_m: float, geometry: _Geometry) -> np.ndarray:
        img = geometry.background.copy()
        if not geometry.bands:
            return img
        shift = np.float32((ego_s_m % sprites.ROAD_TILE_M) / sprites.ROAD_RES_M)
        for lv, r0, r1, mx, my in geometry.bands:
            texels = cv2.remap(self._tex[lv], mx, my + shift / _MIP_FACTORS[lv],
                               cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
            img[r0:r1] = cv2.blendLinear(texels, geometry.background[r0:r1],
                                         geometry.weight[r0:r1], geometry.weight_bg[r0:r1])
        wall_shift = np.float32((ego_s_m % sprites.SCENERY_TILE_M) / sprites.SCENERY_RES_M)
        for lv, y0, y1, x0, x1, mx, my, w in geometry.walls:
            # Nearest texel: less than half the time of bilinear on these large boxes,
            # and at most 1.5 texels a pixel at the nearest level it looks the same.
            texels = cv2.remap(self._wall_tex[lv], mx, my + wall_shift / _MIP_FACTORS[lv],
                               cv2.INTER_NEAREST, borderMode=cv2.BORDER_WRAP)
            region = img[y0:y1, x0:x1]
            region[:] = cv2.blendLinear(texels, region, w, 1.0 - w)
        return img

    def render(self, bodies: list[Body], ego_x_m: float, lights: Sequence[Light] = (),
               headlights: bool = False, road: RoadView | None = None) -> np.ndarray:
        """One BGR uint8 frame of `bodies` and `lights` seen from the ego at (`ego_x_m`,
        0) of a frame along the ego's heading: on a straight road the world frame, on a
        bend the vehicle frame shifted by the ego's station (tools/sim/camera_source.py
        `scene_at`), with `road` saying where on the road the ego is. `headlights`: a
        night scene lit by the ego's low beams (also at the look's night lighting)."""
        return self._draw(bodies, ego_x_m, lights, headlights, None, road)

    def render_rgbd(self, bodies: list[Body], ego_x_m: float, millimetres: bool = False,
                    road: RoadView | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The BGR frame and its aligned depth: (H, W) float32 camera-frame depth in
        metres of what each colour pixel shows, 0 where nothing returns (the sky); with
        `millimetres`, uint16 in DepthFrame's units (common/depth_image.py), converted
        only where objects are drawn (a whole frame's conversion costs 1-2 ms)."""
        geometry = self._geometry(road)
        if millimetres:
            if geometry.depth_mm is None:
                geometry.depth_mm = to_units(geometry.depth)
            depth = geometry.depth_mm.copy()
        else:
            depth = geometry.depth.copy()
        return self._draw(bodies, ego_x_m, (), False, depth, road), depth

    def _draw(self, bodies: list[Body], ego_x_m: float, lights: Sequence[Light],
              headlights: bool, depth: np.ndarray | None, road: RoadView | None) -> np.ndarray:
        self._depth = depth
        headlights = headlights or self.lighting is Lighting.NIGHT
        geometry = self._geometry(road)
        img = self._road(road.s_m if road is not None else ego_x_m, geometry)
        if headlights:
            img = np.clip(img * self._beam_gain(geometry), 0, 255).astype(np.uint8)
        rel = [(b, np.array([b.x_m - ego_x_m, b.y_m])) for b in bodies]
        cam = self.cam_pos[:2]
        rel.sort(key=lambda item: -float(np.hypot(*(item[1] - cam))))
        for body, centre in rel:
            if centre[0] - cam[0] < 0.3 or body.kind is ObjectKind.GHOST:
                continue    # behind the camera, or only the radar's (nothing is there)
            lit = (self._upright_gain(float(centre[0] - cam[0]), float(centre[1] - cam[1]))
                   if headlights else 1.0)
            if body.kind is ObjectKind.PLATE:
                self._plate(img, body, centre, lit)
                continue
            if body.kind is ObjectKind.SIGN:
                self._sign(img, body, centre, lit)
                continue
            self._shadow(img, body, centre)
            if body.kind in (ObjectKind.CAR, ObjectKind.BOX, ObjectKind.GUARD_RAIL):
                self._box(img, body, centre, lit)
            else:
                self._cutout(img, body, centre, lit)
        self._depth = None
        light = self._ambient()
        if light != 1.0 and not headlights:
            img = cv2.convertScaleAbs(img, alpha=light)
        if lights:
            img = self._lights(img, lights, ego_x_m)
        if self.lighting is Lighting.RAIN:
            img = self._rain(img)
        if self._noise:
            up, down = self._noise[self._frame % len(self._noise)]
            grey = self._noise_bgr
            cv2.add(img, cv2.merge((up, up, up), dst=grey), dst=img)
            cv2.subtract(img, cv2.merge((down, down, down), dst=grey), dst=img)
            self._frame += 1
        return img

    # -- light and weather ----------------------------------------------------------------

    def _ambient(self) -> float:
        """The light on the scene relative to a clear day (before the headlights)."""
        return self.look.brightness * AMBIENT[self.lighting]

    def _rain(self, img: np.ndarray) -> np.ndarray:
        """Rain: contrast washed out towards the grey of the spray, then streaks of
        falling drops (a few frames drawn once, used in turn)."""
        img = cv2.addWeighted(img, RAIN_CONTRAST, img, 0.0, (1 - RAIN_CONTRAST) * RAIN_GREY)
        if not self._streaks:
            rng = np.random.default_rng((self._seed, 3))
            for _ in range(_NOISE_BANK):
                layer = np.zeros((self.height, self.width), np.uint8)
                for _ in range(RAIN_STREAKS):
                    x, y = int(rng.integers(0, self.width)), int(rng.integers(0, self.height))
                    n = int(rng.integers(8, 30))
                    cv2.line(layer, (x, y), (x + n // 6, y + n), int(rng.integers(15, 45)), 1,
                             cv2.LINE_AA)
                self._streaks.append(layer)
        streaks = self._streaks[self._frame % len(self._streaks)]
        return cv2.add(img, cv2.merge((streaks, streaks, streaks)))

    def _beam_gain(self, geometry: _Geometry) -> np.ndarray:
        """(H, W, 3) light on each pixel relative to day: the ambient light everywhere,
        plus the low beams on the road ahead (in the vehicle frame: through a bend the
        road curves out of them), which light it at a grazing angle and so fall with
        about the cube of distance."""
        ambient = self._ambient()
        if self._beams is None or self._beams[0] != (ambient, id(geometry)):
            gx, gy = self._ground_xy()
            beam = (geometry.weight > 0) & (gx > 0) & (
                np.abs(gy) < BEAM_SPREAD * gx + BEAM_HALF_WIDTH_M)
            near = np.clip((10.0 / np.maximum(gx, 1.0)) ** 3, 0.0, 1.0)
            gain = ambient + np.where(beam, 0.7 * near, 0.0)
            self._beams = ((ambient, id(geometry)),
                           np.repeat(gain[..., None], 3, axis=2).astype(np.float32))
        return self._beams[1]

    def _upright_gain(self, ahead_m: float, lateral_m: float) -> float:
        """Light on a surface facing the ego `ahead_m` ahead and `lateral_m` to the side
        of the camera: ambient, plus the low beams inside their cone (a soft edge)."""
        edge = BEAM_SPREAD * max(ahead_m, 0.0) + BEAM_HALF_WIDTH_M
        inside = float(np.clip((edge + 1.0 - abs(lateral_m)) / 2.0, 0.0, 1.0))
        return self._ambient() + inside * min((12.0 / max(ahead_m, 1.0)) ** 2, 1.5)

    def _lights(self, img: np.ndarray, lights: Sequence[Light], ego_x_m: float) -> np.ndarray:
        """Saturated lamps and headlights with glow; lamps light a pool of road below them."""
        out = img.astype(np.float32)
        glow = np.zeros(img.shape[:2], np.float32)
        gx, gy = self._ground_xy()
        for light in lights:
            x = light.x_m - ego_x_m
            uv, in_front = self.cal.project(np.array([[x, light.y_m, light.z_m]]))
            if not in_front[0]:
                continue
            radius = max(1.5, self.cal.k[0, 0] * light.radius_m / max(x - self.cam_pos[0], 0.5))
            centre = (int(np.rint(uv[0, 0])), int(np.rint(uv[0, 1])))
            halo = np.zeros_like(glow)
            cv2.circle(halo, centre, int(radius * 3), 1.0, -1, cv2.LINE_AA)
            glow += cv2.GaussianBlur(halo, (0, 0), radius * 2) * 140
            cv2.circle(glow, centre, math.ceil(radius), 400.0, -1, cv2.LINE_AA)
            if light.z_m > 3.0:
                d2 = (gx - x) ** 2 + (gy - light.y_m) ** 2
                pool = np.where(self._straight.weight > 0,
                                1.5 * np.exp(-d2 / (2 * (0.6 * light.z_m) ** 2)), 0.0)
                out *= (1.0 + pool.astype(np.float32))[..., None]
        return np.clip(out + glow[..., None], 0, 255).astype(np.uint8)

    # -- objects --------------------------------------------------------------------------

    def _project(self, points: np.ndarray) -> np.ndarray | None:
        uv, in_front = self.cal.project(points)
        if not in_front.all():
            return None
        return uv.astype(np.float32)

    def _paste(self, img: np.ndarray, sprite: np.ndarray, quad: np.ndarray, shade: float,
               quad3: np.ndarray | None = None) -> None:
        """Warp a BGRA sprite onto an image quad (TL, TR, BR, BL) and blend by alpha;
        when a depth image is being rendered, write the depth of the quad's plane (its
        3-D corners `quad3`, radar ground frame) where the sprite is opaque."""
        x0 = max(math.floor(quad[:, 0].min()), 0)
        y0 = max(math.floor(quad[:, 1].min()), 0)
        x1 = min(math.ceil(quad[:, 0].max()) + 1, self.width)
        y1 = min(math.ceil(quad[:, 1].max()) + 1, self.height)
        if x1 <= x0 or y1 <= y0:
            return
        sh, sw = sprite.shape[:2]
        src = np.array([[0, 0], [sw, 0], [sw, sh], [0, sh]], np.float32)
        m = cv2.getPerspectiveTransform(src, quad - np.array([x0, y0], np.float32))
        warped = cv2.warpPerspective(sprite, m, (x1 - x0, y1 - y0), flags=cv2.INTER_LINEAR,
                                     borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0, 0))
        alpha = warped[:, :, 3].astype(np.float32)
        colour = warped[:, :, :3]
        if shade != 1.0:
            colour = cv2.convertScaleAbs(colour, alpha=shade)
        region = img[y0:y1, x0:x1]
        region[:] = cv2.blendLinear(colour, region, alpha, 255.0 - alpha)
        if self._depth is not None and quad3 is not None:
            self._plane_depth(quad3, (y0, y1, x0, x1), alpha > 127.0)

    def _plane_depth(self, quad3: np.ndarray, box: tuple[int, int, int, int],
                     opaque: np.ndarray) -> None:
        """Depth Z of the plane through `quad3` along each pixel's ray, written where
        `opaque` (the box's pixels the sprite covers)."""
        assert self._depth is not None
        p = quad3 @ self.cal.r.T + self.cal.t             # camera frame
        n = np.cross(p[1] - p[0], p[3] - p[0])
        d = float(n @ p[0])
        y0, y1, x0, x1 = box
        rays = self._norm[y0:y1, x0:x1]
        denom = rays[..., 0] * n[0] + rays[..., 1] * n[1] + n[2]
        with np.errstate(divide="ignore", invalid="ignore"):
            z = d / denom
        ok = opaque & np.isfinite(z) & (z > 0)
        region = self._depth[y0:y1, x0:x1]
        region[ok] = (to_units(np.where(ok, z, 0.0)) if region.dtype == np.uint16 else z)[ok]

    def _sprite(self, body: Body, face: str) -> sprites.Sprite:
        key = (body.index, body.kind.value, face)
        if key not in self._sprites:
            rng = np.random.default_rng((self._seed, body.index, _FACES.index(face)))
            colour = sprites.CAR_COLOURS[(body.index + self._seed) % len(sprites.CAR_COLOURS)]
            h = body.height_m
            if body.kind is ObjectKind.BOX:
                size = body.width_m if face in ("rear", "front") else body.length_m
                sprite = sprites.cardboard(rng, size, h if face != "top" else body.width_m)
            elif body.kind is ObjectKind.GUARD_RAIL:
                sprite = (sprites.plain((150, 152, 155), body.width_m, body.length_m)
                          if face == "top" else sprites.guard_rail(
                              rng, body.length_m if face == "side" else body.width_m, h))
            elif body.kind is ObjectKind.PLATE:
                sprite = sprites.manhole(rng, max(body.length_m, body.width_m))
            elif body.kind is ObjectKind.SIGN:
                sprite = sprites.sign_board(rng, body.width_m, h)
            elif face == "top":
                sprite = sprites.plain(colour, body.width_m, body.length_m)
            elif face == "side":
                sprite = sprites.car_side(colour, rng, body.length_m, h)
            else:
                sprite = sprites.car_rear(colour, rng, body.width_m, h, front=face == "front")
            self._sprites[key] = sprite
        return self._sprites[key]

    def _box(self, img: np.ndarray, body: Body, centre: np.ndarray, lit: float) -> None:
        c = body.corners() - np.array([body.x_m, body.y_m]) + centre
        cam = self.cam_pos
        z0, h = body.z_m, body.z_m + body.height_m
        faces = {0: "side", 1: "rear", 2: "side", 3: "front"}
        for i, face in faces.items():
            a, b = c[i], c[(i + 1) % 4]
            normal = np.array([b[1] - a[1], a[0] - b[0]])
            if np.dot(normal, cam[:2] - (a + b) / 2) <= 0:
                continue
            quad3 = np.array([[a[0], a[1], h], [b[0], b[1], h], [b[0], b[1], z0],
                              [a[0], a[1], z0]])
            quad = self._project(quad3)
            if quad is None:
                continue
            shade = _SHADE_REAR if face != "side" else _SHADE_SIDE
            self._paste(img, self._sprite(body, face).image, quad, shade * lit, quad3)
        if cam[2] > h:
            top = np.array([[c[k][0], c[k][1], h] for k in (3, 0, 1, 2)])
            quad = self._project(top)
            if quad is not None:
                self._paste(img, self._sprite(body, "top").image, quad, _SHADE_TOP * lit, top)

    def _plate(self, img: np.ndarray, body: Body, centre: np.ndarray, lit: float) -> None:
        """A manhole cover or metal plate: flat on the road (a few mm above it)."""
        c = body.corners() - np.array([body.x_m, body.y_m]) + centre
        top = np.array([[c[k][0], c[k][1], min(body.height_m, 0.01)] for k in (3, 0, 1, 2)])
        quad = self._project(top)
        if quad is not None:
            self._paste(img, self._sprite(body, "top").image, quad, lit, top)

    def _sign(self, img: np.ndarray, body: Body, centre: np.ndarray, lit: float) -> None:
        """An overhead sign: its board facing the ego from `z_m` up, on a post at each end
        (the gantry's legs) standing on the ground beside the road."""
        near_x = float(centre[0] - body.length_m / 2)
        half = body.width_m / 2
        z0, z1 = body.z_m, body.z_m + body.height_m
        post = sprites.plain((120, 122, 125), 0.3, z1)
        for y in (centre[1] + half + 0.15, centre[1] - half - 0.15):
            quad3 = np.array([[near_x, y + 0.15, z1], [near_x, y - 0.15, z1],
                              [near_x, y - 0.15, 0.0], [near_x, y + 0.15, 0.0]])
            quad = self._project(quad3)
            if quad is not None:
                self._paste(img, post.image, quad, lit, quad3)
        board = np.array([[near_x, centre[1] + half, z1], [near_x, centre[1] - half, z1],
                          [near_x, centre[1] - half, z0], [near_x, centre[1] + half, z0]])
        quad = self._project(board)
        if quad is not None:
            self._paste(img, self._sprite(body, "rear").image, quad, lit, board)

    def _cutout(self, img: np.ndarray, body: Body, centre: np.ndarray, lit: float) -> None:
        cam = self.cam_pos[:2]
        view = centre - cam
        view /= max(float(np.hypot(*view)), 1e-6)
        right = np.array([view[1], -view[0]])
        speed = math.hypot(body.vx_mps, body.vy_mps)
        heading = (np.array([body.vx_mps, body.vy_mps]) / speed if speed > 0.1 else
                   np.array([math.cos(math.radians(body.yaw_deg)),
                             math.sin(math.radians(body.yaw_deg))]))
        side = abs(float(np.dot(heading, right))) > 0.7
        stride = 0
        if body.kind is ObjectKind.PEDESTRIAN and side and speed > 0.1:
            stride = round(2 * math.sin(2 * math.pi * (abs(body.x_m) + abs(body.y_m)) / 1.4))
        key = f"{'side' if side else 'front'}{stride}"
        cache = (body.index, body.kind.value, key)
        if cache not in self._sprites:
            rng = np.random.default_rng((self._seed, body.index))
            if body.kind is ObjectKind.PEDESTRIAN:
                self._sprites[cache] = sprites.pedestrian(rng, side, stride / 2)
            else:
                self._sprites[cache] = sprites.bicycle(rng, side)
        sprite = self._sprites[cache]
        image = sprite.image
        if side and float(np.dot(heading, right)) < 0:
            flipped = (body.index, body.kind.value, key + "-flipped")
            if flipped not in self._sprites:
                self._sprites[flipped] = sprites.Sprite(
                    np.ascontiguousarray(image[:, ::-1]), sprite.width_m, sprite.height_m)
            image = self._sprites[flipped].image
        scale = body.height_m / 1.75
        half = sprite.width_m * scale / 2
        top = sprite.height_m * scale
        quad3 = np.array([[*(centre - right * half), top], [*(centre + right * half), top],
                          [*(centre + right * half), 0.0], [*(centre - right * half), 0.0]])
        quad = self._project(quad3)
        if quad is not None:
            self._paste(img, image, quad, lit, quad3)

    def _shadow(self, img: np.ndarray, body: Body, centre: np.ndarray) -> None:
        c = (body.corners() - np.array([body.x_m, body.y_m])) * 1.08 + centre
        quad = self._project(np.column_stack([c, np.zeros(4)]))
        if quad is None:
            return
        x0 = max(int(quad[:, 0].min()) - 3, 0)
        y0 = max(int(quad[:, 1].min()) - 3, 0)
        x1 = min(int(quad[:, 0].max()) + 4, self.width)
        y1 = min(int(quad[:, 1].max()) + 4, self.height)
        if x1 <= x0 or y1 <= y0:
            return
        poly = np.zeros((y1 - y0, x1 - x0), np.float32)
        cv2.fillConvexPoly(poly, np.round(quad - [x0, y0]).astype(np.int32), 1.0)
        mask = np.asarray(cv2.GaussianBlur(poly, (0, 0), 1.5), np.float32)
        region = img[y0:y1, x0:x1]
        region[:] = cv2.blendLinear(region, np.zeros_like(region), 1.0 - 0.45 * mask,
                                    0.45 * mask)
