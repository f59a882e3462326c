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

from common.calibration import Calibration
from common.depth_image import to_units
from tools.messages import ObjectKind
from tools.sim import sprites
from tools.sim.scenario import CameraLook
from tools.sim.world import Body

MAX_GROUND_M = 250.0
HAZE_M = 120.0
ROADSIDE_Y_M = 9.5              # hedges and house fronts this far left and right
BACKDROP_M = 150.0              # the far tree line, this far ahead of the camera
BACKDROP_WIDTH_M = 400.0
BACKDROP_RES_M = 0.1
_GEOMETRY_ROWS = 40             # rows per band when building the roadside geometry
BACKDROP_CLARITY = 0.8          # its contrast through the haze (a clear day)
_MIP_FACTORS = (1, 4, 16)        # texture levels: 2 cm, 8 cm, 32 cm per texel
_SHADE_REAR, _SHADE_SIDE, _SHADE_TOP = 1.0, 0.78, 1.12
_NOISE_BANK = 4
_FACES = ("rear", "front", "side", "top")     # a box's faces, in a fixed order


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
    (and roadside) geometry and the textures (one to two seconds); `render` then costs
    about 5 ms for the plain road, 8-10 ms with the roadside, 2 ms more with depth (CPU
    on a quiet core)."""

    def __init__(self, calibration: Calibration, seed: int = 0,
                 look: CameraLook | None = None, roadside: bool = True) -> None:
        self.cal = calibration
        self.look = look or CameraLook()
        self.roadside = roadside
        self._depth: np.ndarray | None = None     # the depth image being rendered
        self._static_depth_mm: np.ndarray | None = None
        self.width, self.height = calibration.width, calibration.height
        self.cam_pos = -calibration.r.T @ calibration.t      # camera centre, ground frame
        self._rng = np.random.default_rng(seed)
        self._seed = seed
        self._night_xy: tuple[np.ndarray, np.ndarray] | None = None
        self._ground_geometry()
        self._textures()
        self._sprites: dict[tuple[int, str, str], sprites.Sprite] = {}
        self._beams: tuple[float, np.ndarray] | None = None
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
        self._make_noise()

    def set_look(self, look: CameraLook) -> None:
        """Change brightness and sensor noise (cheap: the geometry and textures stay)."""
        if look != self.look:
            self.look = look
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
        for _ in range(_NOISE_BANK if self.look.noise > 0 else 0):
            n = np.round(rng.normal(0, self.look.noise, (self.height, self.width)))
            self._noise.append((np.clip(n, 0, 255).astype(np.uint8),
                                np.clip(-n, 0, 255).astype(np.uint8)))
            del n
        release_freed_memory()

    # -- static geometry ----------------------------------------------------------------

    def _ground_hits(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per pixel, float64: whether its ray meets the ground within MAX_GROUND_M, where
        (x, y in the ego's frame, 0 where it does not), how far from the camera, and the
        ray itself in the ground frame ((H, W, 3))."""
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
        """Where each ground pixel is, float32 (the beams and lamp pools at night).
        Computed again on the first night frame rather than kept from the geometry: the
        simulator's camera draws day and dusk only, and would hold 3 MB for nothing."""
        if self._night_xy is None:
            _, gx, gy, _, _ = self._ground_hits()
            self._night_xy = (gx.astype(np.float32), gy.astype(np.float32))
            release_freed_memory()
        return self._night_xy

    def _ground_geometry(self) -> None:
        self.ground, gx, gy, dist, rays = self._ground_hits()
        self._walls: list[tuple[int, int, int, int, int, np.ndarray, np.ndarray, np.ndarray]] = []
        depth = self._ground_z.astype(np.float64)
        backdrop_px: tuple[np.ndarray, np.ndarray] | None = None
        if self.roadside:
            depth, dist, backdrop_px = self._roadside_geometry(rays, depth, dist)
        self.static_depth = depth.astype(np.float32)
        del self._ground_z, depth
        dz = rays[..., 2]
        # Texture coordinates (texels of level 0): column from +y (left) to -y.
        col0 = ((sprites.ROAD_HALF_WIDTH_M - gy) / sprites.ROAD_RES_M).astype(np.float32)
        row0 = (gx / sprites.ROAD_RES_M).astype(np.float32)
        # A texture level per image row, from the row's largest texel footprint (on a
        # level road the footprint grows row by row towards the horizon).
        step = np.abs(np.diff(gx, axis=0, append=gx[-1:])) / sprites.ROAD_RES_M
        step = np.where(self.ground, step, 0.0).max(axis=1)
        row_level = np.where(step > 10.0, 2, np.where(step > 2.5, 1, 0))
        ground_rows = np.nonzero(self.ground.any(axis=1))[0]
        self._bands: list[tuple[int, int, int, np.ndarray, np.ndarray]] = []
        if len(ground_rows):
            r = int(ground_rows[0])
            last = int(ground_rows[-1]) + 1
            while r < last:
                lv = int(row_level[r])
                r_end = r + 1
                while r_end < last and int(row_level[r_end]) == lv:
                    r_end += 1
                f = _MIP_FACTORS[lv]
                self._bands.append((lv, r, r_end, np.ascontiguousarray(col0[r:r_end] / f),
                                    np.ascontiguousarray(row0[r:r_end] / f)))
                r = r_end
        # out = road * weight + bias: haze over distant ground, the sky where no ground.
        fog = 1.0 - np.exp(-np.where(self.ground, dist, MAX_GROUND_M) / HAZE_M)
        ground = self.ground[..., None]
        self._weight = np.where(self.ground, 1.0 - fog, 0.0).astype(np.float32)
        self._weight_bg = (1.0 - self._weight).astype(np.float32)
        elev = np.degrees(np.arctan2(dz, np.hypot(rays[..., 0], rays[..., 1])))
        t = np.clip(elev / 35.0, 0.0, 1.0)[..., None]
        top = np.array([215, 170, 120], np.float64)
        sky = sprites.HAZE_BGR * (1 - t) + top * t
        background = np.where(ground, sprites.HAZE_BGR, sky).astype(np.float32)
        del sky
        if backdrop_px is not None:
            colour, alpha = backdrop_px
            a = (alpha * np.float32(BACKDROP_CLARITY))[..., None]
            background *= 1 - a
            background += colour * a
            del colour, alpha, a
        self._background = background.round().astype(np.uint8)

    def _roadside_geometry(self, rays: np.ndarray, depth: np.ndarray, dist: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
        """Hedges and house fronts at +-ROADSIDE_Y_M and the backdrop BACKDROP_M ahead:
        where each pixel's ray meets them before the ground. Sets the wall bands (texture
        level, box, texture coordinates, weights), hides the ground behind them; returns
        the depth and horizontal distance with them (`depth` and `dist` updated in
        place), and the backdrop's colour and alpha per pixel (it stands still relative
        to the ego, like a far skyline). Computed a band of rows at a time: whole-image
        float64 temporaries would raise the camera process's peak memory by tens of MB."""
        cam = self.cam_pos
        h, w = self.height, self.width
        tex = sprites.backdrop_texture(np.random.default_rng((self._seed, 7)),
                                       BACKDROP_WIDTH_M, BACKDROP_RES_M)
        th, tw = tex.shape[:2]
        wall = np.zeros((h, w), bool)
        solid = np.zeros((h, w), bool)
        zw = np.zeros((h, w), np.float32)
        wx = np.zeros((h, w), np.float32)
        level = np.zeros((h, w), np.uint8)
        colour = np.zeros((h, w, 3), np.uint8)
        alpha = np.zeros((h, w), np.float32)
        for r0 in range(0, h, _GEOMETRY_ROWS):
            r1 = min(r0 + _GEOMETRY_ROWS, h)
            rx, ry, rz = rays[r0:r1, :, 0], rays[r0:r1, :, 1], rays[r0:r1, :, 2]
            d = depth[r0:r1]
            near = np.where(d > 0, d, np.inf)
            # Walls: y = +-ROADSIDE_Y_M, z in [0, SCENERY_HEIGHT_M].
            side = np.where(ry >= 0, ROADSIDE_Y_M, -ROADSIDE_Y_M)
            steep = np.abs(ry) > 1e-9
            sw = np.where(steep, (side - cam[1]) / np.where(steep, ry, 1.0), 1e9)
            z = cam[2] + sw * rz
            hit = (sw > 0) & (z >= 0) & (z <= sprites.SCENERY_HEIGHT_M) & (sw < near) & (
                sw * rx < MAX_GROUND_M)
            near = np.where(hit, sw, near)
            wall[r0:r1], zw[r0:r1], wx[r0:r1] = hit, z, cam[0] + sw * rx
            footprint = sw / self.cal.k[0, 0] / sprites.SCENERY_RES_M   # texels per pixel
            level[r0:r1] = np.where(footprint > 6.0, 2, np.where(footprint > 1.5, 1, 0))
            dist[r0:r1] = np.where(hit, np.hypot(sw * rx, sw * ry), dist[r0:r1])
            # The backdrop: x = cam x + BACKDROP_M, where nothing nearer is hit.
            ahead = rx > 1e-9
            sb = np.where(ahead, BACKDROP_M / np.where(ahead, rx, 1.0), np.inf)
            zb = cam[2] + sb * rz
            col = ((BACKDROP_WIDTH_M / 2 - (cam[1] + sb * ry)) / BACKDROP_RES_M)
            row = ((sprites.BACKDROP_HEIGHT_M - zb) / BACKDROP_RES_M)
            inside = (sb < near) & (col >= 0) & (col < tw) & (row >= 0) & (row < th)
            sampled = cv2.remap(tex, np.where(inside, col, -1).astype(np.float32),
                                np.where(inside, row, -1).astype(np.float32),
                                cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                                borderValue=(0, 0, 0, 0))
            a = np.where(inside, sampled[..., 3] / np.float32(255.0), 0.0)
            opaque = a > 0.5
            solid[r0:r1] = opaque
            alpha[r0:r1] = np.where(opaque, 1.0, a)
            colour[r0:r1] = sampled[..., :3]
            near = np.where(opaque, sb, near)
            d[:] = np.where(np.isfinite(near), near, 0.0)
        self.ground &= ~(wall | solid)
        # Wall texture coordinates (rows along x, columns up) at a level per pixel from
        # its texel footprint; the haze from the horizontal distance.
        for (lv, f), left in itertools.product(enumerate(_MIP_FACTORS), (True, False)):
            mask = wall & (level == lv) & ((rays[..., 1] >= 0) == left)    # a box per side
            if not mask.any():
                continue
            rows_i, cols_i = np.nonzero(mask)
            y0, y1 = int(rows_i.min()), int(rows_i.max()) + 1
            x0, x1 = int(cols_i.min()), int(cols_i.max()) + 1
            m = mask[y0:y1, x0:x1]
            mx = zw[y0:y1, x0:x1] / np.float32(sprites.SCENERY_RES_M * f)
            my = wx[y0:y1, x0:x1] / np.float32(sprites.SCENERY_RES_M * f)
            fog = np.exp(-dist[y0:y1, x0:x1] / HAZE_M)
            weight = np.where(m, fog, 0.0).astype(np.float32)
            self._walls.append((lv, y0, y1, x0, x1, mx, my, weight))
        return depth, dist, (colour, alpha)

    def _textures(self) -> None:
        base = sprites.road_texture(self._rng)
        if self.roadside:
            sprites.road_wear(self._rng, base)
        self._tex = _mip_levels(base)
        self._wall_tex = (_mip_levels(sprites.roadside_texture(self._rng)) if self.roadside
                          else [])

    # -- per frame ------------------------------------------------------------------------

    def _road(self, ego_x_m: float) -> np.ndarray:
        img = self._background.copy()
        if not self._bands:
            return img
        shift = np.float32((ego_x_m % sprites.ROAD_TILE_M) / sprites.ROAD_RES_M)
        for lv, r0, r1, mx, my in self._bands:
            texels = cv2.remap(self._tex[lv], mx, my + shift / _MIP_FACTORS[lv],
                               cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
            img[r0:r1] = cv2.blendLinear(texels, self._background[r0:r1],
                                         self._weight[r0:r1], self._weight_bg[r0:r1])
        wall_shift = np.float32((ego_x_m % sprites.SCENERY_TILE_M) / sprites.SCENERY_RES_M)
        for lv, y0, y1, x0, x1, mx, my, w in self._walls:
            # Nearest texel: less than half the time of bilinear on these large boxes,
            # and at most 1.5 texels a pixel at the nearest level it looks the same.
            texels = cv2.remap(self._wall_tex[lv], mx, my + wall_shift / _MIP_FACTORS[lv],
                               cv2.INTER_NEAREST, borderMode=cv2.BORDER_WRAP)
            region = img[y0:y1, x0:x1]
            region[:] = cv2.blendLinear(texels, region, w, 1.0 - w)
        return img

    def render(self, bodies: list[Body], ego_x_m: float, lights: Sequence[Light] = (),
               headlights: bool = False) -> np.ndarray:
        """One BGR uint8 frame of `bodies` and `lights` (world frame) seen from the ego at
        `ego_x_m`; `headlights`: a night scene lit by the ego's low beams."""
        return self._draw(bodies, ego_x_m, lights, headlights, None)

    def render_rgbd(self, bodies: list[Body], ego_x_m: float, millimetres: bool = False
                    ) -> tuple[np.ndarray, np.ndarray]:
        """The BGR frame and its aligned depth: (H, W) float32 camera-frame depth in
        metres of what each colour pixel shows, 0 where nothing returns (the sky); with
        `millimetres`, uint16 in DepthFrame's units (common/depth_image.py), converted
        only where objects are drawn (a whole frame's conversion costs 1-2 ms)."""
        if millimetres:
            if self._static_depth_mm is None:
                self._static_depth_mm = to_units(self.static_depth)
            depth = self._static_depth_mm.copy()
        else:
            depth = self.static_depth.copy()
        return self._draw(bodies, ego_x_m, (), False, depth), depth

    def _draw(self, bodies: list[Body], ego_x_m: float, lights: Sequence[Light],
              headlights: bool, depth: np.ndarray | None) -> np.ndarray:
        self._depth = depth
        img = self._road(ego_x_m)
        if headlights:
            img = np.clip(img * self._beam_gain(), 0, 255).astype(np.uint8)
        rel = [(b, np.array([b.x_m - ego_x_m, b.y_m])) for b in bodies]
        cam = self.cam_pos[:2]
        rel.sort(key=lambda item: -float(np.hypot(*(item[1] - cam))))
        for body, centre in rel:
            if centre[0] - cam[0] < 0.3 or body.kind is ObjectKind.GHOST:
                continue    # behind the camera, or only the radar's (nothing is there)
            lit = self._upright_gain(float(centre[0] - cam[0])) if headlights else 1.0
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
        brightness = self.look.brightness
        if brightness != 1.0 and not headlights:
            img = cv2.convertScaleAbs(img, alpha=brightness)
        if lights:
            img = self._lights(img, lights, ego_x_m)
        if self._noise:
            up, down = self._noise[self._frame % len(self._noise)]
            grey = self._noise_bgr
            cv2.add(img, cv2.merge((up, up, up), dst=grey), dst=img)
            cv2.subtract(img, cv2.merge((down, down, down), dst=grey), dst=img)
            self._frame += 1
        return img

    # -- night ----------------------------------------------------------------------------

    def _beam_gain(self) -> np.ndarray:
        """(H, W, 3) light on each pixel relative to day: the ambient light everywhere,
        plus the low beams on the road ahead, which light it at a grazing angle and so
        fall with about the cube of distance."""
        ambient = self.look.brightness
        if self._beams is None or self._beams[0] != ambient:
            gx, gy = self._ground_xy()
            beam = self.ground & (gx > 0) & (np.abs(gy) < 0.25 * gx + 1.5)
            near = np.clip((10.0 / np.maximum(gx, 1.0)) ** 3, 0.0, 1.0)
            gain = ambient + np.where(beam, 0.7 * near, 0.0)
            self._beams = (ambient, np.repeat(gain[..., None], 3, axis=2).astype(np.float32))
        return self._beams[1]

    def _upright_gain(self, distance_m: float) -> float:
        """Light on a surface facing the ego `distance_m` ahead: ambient plus low beams."""
        return self.look.brightness + min((12.0 / max(distance_m, 1.0)) ** 2, 1.5)

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
                pool = np.where(self.ground, 1.5 * np.exp(-d2 / (2 * (0.6 * light.z_m) ** 2)),
                                0.0)
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
