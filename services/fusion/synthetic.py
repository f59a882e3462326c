"""SIMULATION: synthetic road scenes for testing and benchmarking the gate.

Renders, with numpy and OpenCV only, a colour frame as a calibrated camera would see it:
sky, a textured asphalt ground plane in perspective, lane markings, roadside clutter
near the horizon, and obstacles standing on the ground at radar-frame positions. A night
variant darkens the scene, lights the near road and obstacles with headlights, and adds
street lamps, oncoming headlights (saturated blobs with glow) and sensor noise: the
conditions in which the paper's gate lost precision. These images are not camera data;
they exist so that tests and benchmarks have real-looking pixels with known ground truth.
The road is rendered with the pinhole model (distortion ignored); obstacles are projected
with the full calibration.
"""

from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from common.calibration import Calibration

ObstacleKind = Literal["box", "pedestrian", "car"]


@dataclass(frozen=True)
class Obstacle:
    """An obstacle standing on the ground; (x_m, y_m) is the centre of its front face."""

    x_m: float
    y_m: float
    kind: ObstacleKind = "box"
    width_m: float = 0.6
    height_m: float = 0.6


@dataclass(frozen=True)
class Light:
    """A light source (lamp, headlight) at a radar-frame position, drawn saturated."""

    x_m: float
    y_m: float
    z_m: float
    radius_m: float = 0.15


@dataclass(frozen=True)
class Scene:
    obstacles: tuple[Obstacle, ...] = ()
    night: bool = False
    lights: tuple[Light, ...] = ()
    noise_sigma: float = 0.0       # sensor noise (grey levels) added before JPEG
    seed: int = 0
    clutter: bool = True           # buildings and trees near the horizon
    lane_half_width_m: float = 1.75


def _ground_coordinates(cal: Calibration) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ground-plane (x, y) seen by every pixel, and a mask of pixels that see the ground."""
    h, w = cal.height, cal.width
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    rays = np.stack([(u - cal.k[0, 2]) / cal.k[0, 0], (v - cal.k[1, 2]) / cal.k[1, 1],
                     np.ones_like(u)], axis=-1)
    d = rays @ cal.r            # R^T d for each pixel: directions in the ground frame
    centre = -cal.r.T @ cal.t
    dz = d[..., 2]
    ground = dz < -1e-6
    s = np.where(ground, -centre[2] / np.where(ground, dz, -1.0), 0.0)
    gx = centre[0] + s * d[..., 0]
    gy = centre[1] + s * d[..., 1]
    ground &= gx < 400.0
    gx = np.where(ground, gx, 1e3)
    gy = np.where(ground, gy, 0.0)
    return gx, gy, ground


def _value_noise(rng: np.random.Generator, shape: tuple[int, int], scale: int) -> np.ndarray:
    """Smooth noise in [-1, 1] at a given pixel scale."""
    small = rng.uniform(-1, 1, (shape[0] // scale + 2, shape[1] // scale + 2)).astype(np.float32)
    big = cv2.resize(small, (shape[1] + 2 * scale, shape[0] + 2 * scale),
                     interpolation=cv2.INTER_CUBIC)
    return big[scale:scale + shape[0], scale:scale + shape[1]]


def _project(cal: Calibration, pts: np.ndarray) -> np.ndarray | None:
    uv, ok = cal.project(np.asarray(pts, dtype=np.float64))
    return None if not ok.all() else uv


def _draw_obstacle(img: np.ndarray, cal: Calibration, ob: Obstacle,
                   rng: np.random.Generator, light: float) -> None:
    hw = ob.width_m / 2
    corners = np.array([[ob.x_m, ob.y_m + hw, 0], [ob.x_m, ob.y_m - hw, 0],
                        [ob.x_m, ob.y_m - hw, ob.height_m], [ob.x_m, ob.y_m + hw, ob.height_m]])
    uv = _project(cal, corners)
    if uv is None:
        return
    x0, y0 = uv.min(axis=0)
    x1, y1 = uv.max(axis=0)
    bw, bh = max(x1 - x0, 1.0), max(y1 - y0, 1.0)

    def shade(bgr: tuple[int, int, int]) -> tuple[int, int, int]:
        return tuple(int(min(255, c * light)) for c in bgr)  # type: ignore[return-value]

    def rect(fx0: float, fy0: float, fx1: float, fy1: float, bgr: tuple[int, int, int]) -> None:
        cv2.rectangle(img, (int(x0 + fx0 * bw), int(y0 + fy0 * bh)),
                      (int(x0 + fx1 * bw), int(y0 + fy1 * bh)), shade(bgr), -1, cv2.LINE_AA)

    if ob.kind == "box":
        cv2.fillConvexPoly(img, uv.astype(np.int32), shade((60, 120, 170)), cv2.LINE_AA)
        rect(0.0, 0.42, 1.0, 0.56, (150, 170, 190))               # tape
        rect(0.1, 0.1, 0.35, 0.3, (30, 40, 60))                   # printed label
        cv2.polylines(img, [uv.astype(np.int32)], True, shade((35, 70, 100)), 2, cv2.LINE_AA)
    elif ob.kind == "pedestrian":
        rect(0.25, 0.2, 0.75, 0.6, (110, 60, 40))                 # jacket
        rect(0.3, 0.6, 0.48, 1.0, (50, 40, 35))                   # legs
        rect(0.52, 0.6, 0.7, 1.0, (50, 40, 35))
        rect(0.1, 0.22, 0.25, 0.55, (110, 60, 40))                # arms
        rect(0.75, 0.22, 0.9, 0.55, (110, 60, 40))
        cx, cy = int(x0 + 0.5 * bw), int(y0 + 0.1 * bh)
        cv2.circle(img, (cx, cy), max(2, int(0.1 * bh)), shade((120, 150, 190)), -1, cv2.LINE_AA)
    else:  # car seen from behind
        cv2.fillConvexPoly(img, uv.astype(np.int32), shade((70, 70, 150)), cv2.LINE_AA)
        rect(0.12, 0.05, 0.88, 0.4, (60, 50, 45))                 # rear window
        rect(0.05, 0.5, 0.2, 0.62, (20, 20, 200))                 # tail lights
        rect(0.8, 0.5, 0.95, 0.62, (20, 20, 200))
        rect(0.35, 0.6, 0.65, 0.72, (200, 200, 200))              # plate
        rect(0.0, 0.8, 1.0, 0.9, (40, 40, 40))                    # bumper
    # Surface texture: what a real object's print, folds and seams give the gate.
    ix0, iy0 = max(int(x0), 0), max(int(y0), 0)
    ix1, iy1 = min(int(x1), img.shape[1]), min(int(y1), img.shape[0])
    if ix1 - ix0 > 2 and iy1 - iy0 > 2:
        tex = _value_noise(rng, (iy1 - iy0, ix1 - ix0), 3) * 14 * light
        patch = img[iy0:iy1, ix0:ix1].astype(np.float32) + tex[..., None]
        img[iy0:iy1, ix0:ix1] = np.clip(patch, 0, 255).astype(np.uint8)


def render(cal: Calibration, scene: Scene) -> np.ndarray:
    """A BGR uint8 frame of the scene (cal.width x cal.height)."""
    rng = np.random.default_rng(scene.seed)
    h, w = cal.height, cal.width
    gx, gy, ground = _ground_coordinates(cal)
    img = np.zeros((h, w, 3), np.float32)
    # Sky: a vertical gradient.
    rows = np.linspace(0, 1, h, dtype=np.float32)[:, None]
    sky = np.stack([235 - 60 * rows, 215 - 50 * rows, 190 - 50 * rows], axis=-1)
    img[:] = np.broadcast_to(sky, (h, w, 3))
    # Ground: asphalt on the road, grass beside it; texture fades with distance.
    dist = gx
    fade = np.clip(8.0 / np.maximum(dist, 1.0), 0.15, 1.0)
    grain = _value_noise(rng, (h, w), 2) * 6 + _value_noise(rng, (h, w), 9) * 8
    on_road = ground & (np.abs(gy) < scene.lane_half_width_m * 2.2)
    asphalt = 105 + grain * fade
    grass = 80 + _value_noise(rng, (h, w), 4) * 14 * fade
    for c, (a, g) in enumerate(((1.0, 0.55), (1.0, 1.05), (1.0, 0.7))):
        img[..., c] = np.where(on_road, asphalt * a, np.where(ground, grass * g, img[..., c]))
    # Dashed lane markings at +-lane_half_width_m.
    dash = (np.mod(gx, 9.0) < 3.0) & (gx > 2.0)
    for side in (-1, 1):
        line = ground & dash & (np.abs(gy - side * scene.lane_half_width_m) < 0.07)
        img[line] = (225, 225, 225)
    img_u8 = np.clip(img, 0, 255).astype(np.uint8)
    if scene.clutter:
        _draw_clutter(img_u8, cal, rng)
    if scene.night:
        img_u8 = np.clip(_night_background(img_u8.astype(np.float32), gx, gy, ground),
                         0, 255).astype(np.uint8)
    for ob in sorted(scene.obstacles, key=lambda o: -o.x_m):
        lit = float(_headlight(ob.x_m, "upright")) if scene.night else 1.0
        _draw_obstacle(img_u8, cal, ob, rng, lit)
    out = img_u8.astype(np.float32)
    if scene.night:
        out = _add_lights(out, cal, gx, gy, ground, scene.lights)
    if scene.noise_sigma > 0:
        out += rng.normal(0.0, scene.noise_sigma, out.shape[:2])[..., None].astype(np.float32)
    return np.clip(out, 0, 255).astype(np.uint8)


_AMBIENT = 0.12


def _headlight(distance_m: np.ndarray | float, surface: Literal["road", "upright"]
               ) -> np.ndarray | float:
    """Night illumination relative to day: ambient plus low beams. An upright surface
    facing the car receives light falling with the square of distance; the road, lit at
    a grazing angle, falls about one power faster."""
    d = np.maximum(distance_m, 1.0)
    if surface == "road":
        return _AMBIENT + 0.7 * np.clip((10.0 / d) ** 3, 0.0, 1.0)
    return _AMBIENT + np.clip((12.0 / d) ** 2, 0.0, 1.5)


def _draw_clutter(img: np.ndarray, cal: Calibration, rng: np.random.Generator) -> None:
    """Buildings and trees 40-80 m away on both sides of the road."""
    for _ in range(14):
        side = rng.choice([-1.0, 1.0])
        x = rng.uniform(40, 80)
        y = side * rng.uniform(9, 30)
        width, height = rng.uniform(4, 12), rng.uniform(3, 12)
        pts = np.array([[x, y - width / 2, 0], [x, y + width / 2, 0],
                        [x, y + width / 2, height], [x, y - width / 2, height]])
        uv = _project(cal, pts)
        if uv is None:
            continue
        grey = int(rng.uniform(90, 170))
        colour = (grey, int(grey * rng.uniform(0.9, 1.1)), int(grey * rng.uniform(0.8, 1.0)))
        cv2.fillConvexPoly(img, uv.astype(np.int32), colour, cv2.LINE_AA)
        x0, y0 = uv.min(axis=0).astype(int)
        x1, y1 = uv.max(axis=0).astype(int)
        for _ in range(int(rng.integers(2, 8))):  # windows
            wx = int(rng.uniform(x0, max(x0 + 1, x1 - 3)))
            wy = int(rng.uniform(y0, max(y0 + 1, y1 - 3)))
            cv2.rectangle(img, (wx, wy), (wx + 2, wy + 3), (50, 50, 60), -1)


def _night_background(img: np.ndarray, gx: np.ndarray, gy: np.ndarray,
                      ground: np.ndarray) -> np.ndarray:
    """Ambient light everywhere, low beams on the road ahead."""
    beam = ground & (gx > 0) & (np.abs(gy) < 0.25 * gx + 1.5)
    gain = np.where(beam, _headlight(np.where(beam, gx, 1.0), "road"), _AMBIENT)
    return img * gain[..., None].astype(np.float32)


def _add_lights(img: np.ndarray, cal: Calibration, gx: np.ndarray, gy: np.ndarray,
                ground: np.ndarray, lights: tuple[Light, ...]) -> np.ndarray:
    """Saturated lamps and headlights with glow; lamps light a pool of road below them."""
    out = img.copy()
    glow = np.zeros(img.shape[:2], np.float32)
    cam_x = float((-cal.r.T @ cal.t)[0])
    for light in lights:
        uv, ok = cal.project(np.array([[light.x_m, light.y_m, light.z_m]]))
        if not ok[0]:
            continue
        radius = max(1.5, cal.k[0, 0] * light.radius_m / max(light.x_m - cam_x, 0.5))
        centre = (int(np.rint(uv[0, 0])), int(np.rint(uv[0, 1])))
        halo = np.zeros_like(glow)
        cv2.circle(halo, centre, int(radius * 3), 1.0, -1, cv2.LINE_AA)
        glow += cv2.GaussianBlur(halo, (0, 0), radius * 2) * 140
        cv2.circle(glow, centre, int(np.ceil(radius)), 400.0, -1, cv2.LINE_AA)
        if light.z_m > 3.0:
            d2 = (gx - light.x_m) ** 2 + (gy - light.y_m) ** 2
            pool = np.where(ground, 1.5 * np.exp(-d2 / (2 * (0.6 * light.z_m) ** 2)), 0.0)
            out *= (1.0 + pool.astype(np.float32))[..., None]
    return out + glow[..., None]


_SIZES: dict[str, tuple[float, float]] = {
    "box": (0.6, 0.6), "pedestrian": (0.5, 1.75), "car": (1.7, 1.4)}


@dataclass(frozen=True)
class LabelledFrame:
    """One synthetic frame (JPEG, as the camera would publish it) and a track position
    at which an obstacle stands (`obstacle` True) or the road is empty."""

    jpeg: bytes
    track_xy: tuple[float, float]
    obstacle: bool
    night: bool
    noise_sigma: float
    kind: str


def labelled_frames(cal: Calibration, n: int, seed: int = 0, night_share: float = 0.5,
                    quality: int = 80) -> list[LabelledFrame]:
    """`n` frames, half with an obstacle at the track, half with an empty road there.

    Night frames get 1-3 oncoming headlights and 0-2 street lamps at random places ahead,
    and sensor noise of 0-6 grey levels; day frames 0-2 grey levels.
    """
    from common.imaging import encode_jpeg

    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        night = bool(rng.random() < night_share)
        noise = float(rng.choice([0.0, 2.0, 4.0, 6.0] if night else [0.0, 2.0]))
        lights: list[Light] = []
        if night:
            lights += [Light(rng.uniform(45, 120), rng.uniform(-3, 4), 0.7, 0.1)
                       for _ in range(int(rng.integers(1, 4)))]
            lights += [Light(rng.uniform(30, 120), rng.uniform(-8, 8), rng.uniform(5, 8), 0.25)
                       for _ in range(int(rng.integers(0, 3)))]
        x, y = float(rng.uniform(6, 25)), float(rng.uniform(-1.2, 1.2))
        obstacle = i % 2 == 0
        kind = str(rng.choice(list(_SIZES)))
        w, h = _SIZES[kind]
        obstacles = (Obstacle(x, y, kind, w, h),) if obstacle else ()  # type: ignore[arg-type]
        scene = Scene(obstacles=obstacles, night=night, lights=tuple(lights),
                      noise_sigma=noise, seed=seed * 100_003 + i)
        out.append(LabelledFrame(encode_jpeg(render(cal, scene), quality), (x, y), obstacle,
                                 night, noise, kind if obstacle else "road"))
    return out


# A SIMULATED camera rig for multi-camera tests and benchmarks: the example D435
# intrinsics (848x480), cameras 1.3 m up; front (the example calibration's pose), two
# corner cameras turned 55 degrees, and a narrow front camera (twice the focal length).
RIG: dict[str, tuple[float, tuple[float, float, float], float]] = {
    # name: (yaw_deg, position_m, focal length px)
    "front": (0.0, (-0.8, 0.0, 1.3), 615.0),
    "left": (55.0, (-0.6, 0.7, 1.3), 615.0),
    "right": (-55.0, (-0.6, -0.7, 1.3), 615.0),
    "narrow": (0.0, (-0.8, 0.1, 1.3), 1230.0),
}


def rig_calibration_toml(name: str) -> str:
    """One RIG camera as a calibration TOML (common/calibration.py format)."""
    yaw, (px, py, pz), f = RIG[name]
    return f'''name = "synthetic-rig-{name}"
[camera]
width = 848
height = 480
fx = {f}
fy = {f}
cx = 424.0
cy = 240.0
distortion = [0.0, 0.0, 0.0, 0.0, 0.0]
[extrinsics.pose]
position_m = [{px}, {py}, {pz}]
yaw_deg = {yaw}
'''
