"""Procedural textures for the simulated camera: road, grass, sky, and the faces of cars,
boxes, pedestrians and bicycles (BGRA, alpha marks the object's silhouette).

Drawn so that Canny sees what it would see on real objects: edges where a car has panel
gaps, windows, lights, a plate and wheels, a cardboard box its tape, print and folds, a
person their outline, clothes and limbs; and few edges on asphalt and sky (low-contrast,
smooth texture). Deterministic for a given seed.
"""

from dataclasses import dataclass

import cv2
import numpy as np

PX_PER_M = 200          # object textures
ROAD_RES_M = 0.02       # road texture: metres per texel
ROAD_TILE_M = 24.0      # the road texture repeats every ROAD_TILE_M along x
ROAD_HALF_WIDTH_M = 16.0
LANE_WIDTH_M = 3.5


@dataclass(frozen=True)
class Sprite:
    """A BGRA texture and the physical size it spans (width, height) in metres."""

    image: np.ndarray
    width_m: float
    height_m: float


def _blur_noise(rng: np.random.Generator, shape: tuple[int, int], sigma: float,
                amplitude: float) -> np.ndarray:
    noise = cv2.GaussianBlur(rng.normal(0, 1, shape).astype(np.float32), (0, 0), sigma)
    return np.asarray(noise * (amplitude / max(float(noise.std()), 1e-6)), np.float32)


def road_texture(rng: np.random.Generator) -> np.ndarray:
    """BGR, rows along x (ROAD_TILE_M), columns along y from +ROAD_HALF_WIDTH_M (left,
    column 0) to -ROAD_HALF_WIDTH_M: three lanes, markings, shoulders and grass."""
    rows = round(ROAD_TILE_M / ROAD_RES_M)
    cols = round(2 * ROAD_HALF_WIDTH_M / ROAD_RES_M)
    y = ROAD_HALF_WIDTH_M - (np.arange(cols) + 0.5) * ROAD_RES_M      # left positive
    x = (np.arange(rows) + 0.5) * ROAD_RES_M
    grain = _blur_noise(rng, (rows, cols), 2.0, 3.0) + _blur_noise(rng, (rows, cols), 12.0, 4.0)
    img = np.empty((rows, cols, 3), np.float32)
    asphalt = np.array([98, 98, 96], np.float32)
    grass = np.array([60, 120, 85], np.float32)
    gravel = np.array([120, 130, 135], np.float32)
    road_edge = 1.5 * LANE_WIDTH_M
    ay = np.abs(y)
    base = np.where(ay[:, None] <= road_edge + 0.6, 1, 0)
    img[:] = asphalt
    shoulder = (ay > road_edge + 0.3) & (ay <= road_edge + 1.2)
    img[:, shoulder] = gravel
    img[:, ay > road_edge + 1.2] = grass
    img += grain[:, :, None] * np.where(base.T == 1, 1.0, 2.5)[:, :, None]
    white = np.array([225, 228, 230], np.float32)
    # Solid edge lines; dashed lane lines (3 m marked, 6 m gap) between the lanes.
    for edge in (road_edge, -road_edge):
        img[:, np.abs(y - edge) < 0.075] = white
    dash = (x % 9.0) < 3.0
    for lane_line in (LANE_WIDTH_M / 2, -LANE_WIDTH_M / 2):
        cols_line = np.abs(y - lane_line) < 0.06
        img[np.ix_(dash, cols_line)] = white
    # Worn paint: markings are not perfectly uniform.
    img += _blur_noise(rng, (rows, cols), 1.0, 2.0)[:, :, None]
    return np.clip(img, 0, 255).astype(np.uint8)


def sky_column(height: int) -> np.ndarray:
    """(height, 3) BGR: deep blue at the top to a pale haze at the horizon."""
    t = np.linspace(0.0, 1.0, height, dtype=np.float32)[:, None]
    top = np.array([215, 170, 120], np.float32)
    low = np.array([238, 228, 215], np.float32)
    return (top * (1 - t) + low * t).astype(np.uint8)


HAZE_BGR = np.array([225, 222, 215], np.float32)


def _canvas(width_m: float, height_m: float) -> np.ndarray:
    return np.zeros((round(height_m * PX_PER_M), round(width_m * PX_PER_M), 4), np.uint8)


def _px(v_m: float) -> int:
    return round(v_m * PX_PER_M)


def _rect(img: np.ndarray, x0: float, y0: float, x1: float, y1: float,
          colour: tuple[int, int, int], thickness: int = -1) -> None:
    """A rectangle in fractions of the texture (0..1), y from the top."""
    h, w = img.shape[:2]
    cv2.rectangle(img, (round(x0 * w), round(y0 * h)), (round(x1 * w), round(y1 * h)),
                  (*colour, 255), thickness)


def _shade(img: np.ndarray, rng: np.random.Generator, amount: float = 6.0) -> None:
    """Low-contrast surface variation inside the silhouette (paint, dirt)."""
    noise = _blur_noise(rng, img.shape[:2], 3.0, amount)
    rgb = img[:, :, :3].astype(np.float32) + noise[:, :, None]
    img[:, :, :3] = np.clip(rgb, 0, 255).astype(np.uint8)


def plain(colour: tuple[int, int, int], width_m: float, height_m: float) -> Sprite:
    img = _canvas(width_m, height_m)
    img[:] = (*colour, 255)
    return Sprite(img, width_m, height_m)


CAR_COLOURS = [(40, 40, 160), (150, 110, 40), (200, 200, 200), (45, 45, 45), (30, 110, 30),
               (170, 170, 175)]


def car_rear(colour: tuple[int, int, int], rng: np.random.Generator, width_m: float,
             height_m: float, front: bool = False) -> Sprite:
    img = _canvas(width_m, height_m)
    h, w = img.shape[:2]
    dark = (30, 30, 32)
    # Body below the belt line, narrower cabin above it.
    _rect(img, 0.0, 0.42, 1.0, 0.92, colour)
    cabin = np.array([[0.08 * w, 0.42 * h], [0.2 * w, 0.05 * h], [0.8 * w, 0.05 * h],
                      [0.92 * w, 0.42 * h]], np.int32)
    cv2.fillConvexPoly(img, cabin, (*colour, 255))
    glass = np.array([[0.14 * w, 0.40 * h], [0.24 * w, 0.1 * h], [0.76 * w, 0.1 * h],
                      [0.86 * w, 0.40 * h]], np.int32)
    cv2.fillConvexPoly(img, glass, (70, 60, 50, 255))
    cv2.line(img, (round(0.3 * w), round(0.15 * h)), (round(0.22 * w), round(0.36 * h)),
             (150, 140, 130, 255), 3)   # reflection
    _rect(img, 0.0, 0.80, 1.0, 0.92, dark)                     # bumper
    _rect(img, 0.05, 0.92, 0.2, 1.0, (15, 15, 15))             # wheels below the bumper
    _rect(img, 0.8, 0.92, 0.95, 1.0, (15, 15, 15))
    if front:
        _rect(img, 0.05, 0.5, 0.25, 0.6, (220, 230, 235))      # headlights
        _rect(img, 0.75, 0.5, 0.95, 0.6, (220, 230, 235))
        _rect(img, 0.32, 0.62, 0.68, 0.76, dark)               # grille
        for k in range(5):
            y = 0.64 + 0.025 * k
            cv2.line(img, (round(0.33 * w), round(y * h)), (round(0.67 * w), round(y * h)),
                     (90, 90, 90, 255), 2)
    else:
        _rect(img, 0.03, 0.48, 0.2, 0.6, (30, 30, 200))        # tail lights
        _rect(img, 0.8, 0.48, 0.97, 0.6, (30, 30, 200))
        _rect(img, 0.05, 0.5, 0.12, 0.56, (60, 150, 240))      # indicators
        _rect(img, 0.88, 0.5, 0.95, 0.56, (60, 150, 240))
        cv2.line(img, (round(0.2 * w), round(0.62 * h)), (round(0.8 * w), round(0.62 * h)),
                 (*(max(c - 60, 0) for c in colour), 255), 2)  # trunk lid gap
    _rect(img, 0.38, 0.64, 0.62, 0.76, (235, 235, 235))        # plate
    for k in range(6):
        x0 = 0.40 + 0.036 * k
        _rect(img, x0, 0.665, x0 + 0.022, 0.735, (20, 20, 20))
    cv2.rectangle(img, (0, round(0.42 * h)), (w - 1, round(0.92 * h)), (*dark, 255), 2)
    _shade(img, rng)
    return Sprite(img, width_m, height_m)


def car_side(colour: tuple[int, int, int], rng: np.random.Generator, length_m: float,
             height_m: float) -> Sprite:
    img = _canvas(length_m, height_m)
    h, w = img.shape[:2]
    dark = (30, 30, 32)
    _rect(img, 0.0, 0.42, 1.0, 0.85, colour)
    cabin = np.array([[0.2 * w, 0.42 * h], [0.32 * w, 0.05 * h], [0.72 * w, 0.05 * h],
                      [0.85 * w, 0.42 * h]], np.int32)
    cv2.fillConvexPoly(img, cabin, (*colour, 255))
    for x0, x1 in ((0.26, 0.5), (0.52, 0.8)):
        win = np.array([[x0 * w, 0.4 * h], [(x0 + 0.06) * w, 0.1 * h],
                        [(x1 - 0.04) * w, 0.1 * h], [x1 * w, 0.4 * h]], np.int32)
        cv2.fillConvexPoly(img, win, (70, 60, 50, 255))
    for x in (0.51,):
        cv2.line(img, (round(x * w), round(0.42 * h)), (round(x * w), round(0.85 * h)),
                 (*dark, 255), 2)   # door gap
    for x in (0.42, 0.64):
        _rect(img, x, 0.5, x + 0.04, 0.53, dark)   # handles
    r = _px(0.33)
    for x in (0.18, 0.82):
        centre = (round(x * w), h - r)
        cv2.circle(img, centre, r, (15, 15, 15, 255), -1)
        cv2.circle(img, centre, round(r * 0.55), (150, 150, 150, 255), -1)
        for k in range(5):
            a = k * 2 * np.pi / 5
            tip = (round(centre[0] + 0.5 * r * np.cos(a)), round(centre[1] + 0.5 * r * np.sin(a)))
            cv2.line(img, centre, tip, (60, 60, 60, 255), 3)
    _shade(img, rng)
    return Sprite(img, length_m, height_m)


def cardboard(rng: np.random.Generator, width_m: float, height_m: float) -> Sprite:
    img = _canvas(width_m, height_m)
    h, w = img.shape[:2]
    img[:] = (80, 135, 182, 255)
    _shade(img, rng, 8.0)
    _rect(img, 0.0, 0.44, 1.0, 0.56, (150, 185, 205))      # tape
    _rect(img, 0.1, 0.1, 0.45, 0.3, (235, 235, 235))       # shipping label
    for k in range(4):
        _rect(img, 0.13, 0.13 + 0.04 * k, 0.4, 0.145 + 0.04 * k, (40, 40, 40))
    cv2.putText(img, "FRAGILE", (round(0.52 * w), round(0.3 * h)), cv2.FONT_HERSHEY_SIMPLEX,
                0.9, (30, 30, 150, 255), 3)
    cv2.putText(img, "THIS SIDE UP", (round(0.15 * w), round(0.82 * h)),
                cv2.FONT_HERSHEY_SIMPLEX, 0.7, (30, 30, 30, 255), 2)
    cv2.arrowedLine(img, (round(0.85 * w), round(0.9 * h)), (round(0.85 * w), round(0.65 * h)),
                    (30, 30, 30, 255), 4)
    cv2.rectangle(img, (0, 0), (w - 1, h - 1), (40, 70, 100, 255), 3)   # folded edges
    return Sprite(img, width_m, height_m)


SHIRTS = [(160, 60, 40), (40, 40, 170), (50, 140, 60), (200, 200, 200), (40, 160, 200)]


def pedestrian(rng: np.random.Generator, side: bool, stride: float = 0.0) -> Sprite:
    """A person 1.75 m tall; `side` for a side view, `stride` (-1..1) the leg swing."""
    width_m, height_m = (0.7, 1.8) if side else (0.6, 1.8)
    img = _canvas(width_m, height_m)
    h, w = img.shape[:2]
    cx = w // 2
    skin, hair = (120, 150, 200), (30, 40, 60)
    shirt = SHIRTS[int(rng.integers(len(SHIRTS)))]
    trousers = (70, 50, 40)
    head_r = _px(0.11)
    head_c = (cx, _px(0.05) + head_r)
    cv2.circle(img, head_c, head_r, (*skin, 255), -1)
    cv2.ellipse(img, (head_c[0], head_c[1] - head_r // 3), (head_r, head_r * 2 // 3), 0, 180,
                360, (*hair, 255), -1)
    torso_top, torso_bot = _px(0.33), _px(0.95)
    half = _px(0.12 if side else 0.2)
    cv2.rectangle(img, (cx - half, torso_top), (cx + half, torso_bot), (*shirt, 255), -1)
    for k in range(3):   # shirt stripes
        y = torso_top + (k + 1) * (torso_bot - torso_top) // 4
        cv2.line(img, (cx - half, y), (cx + half, y), (*(c // 2 for c in shirt), 255), 4)
    leg = _px(0.08)
    hip, foot = torso_bot, h - _px(0.04)
    if side:
        for sgn in (-1, 1):
            dx = round(sgn * stride * _px(0.25))
            cv2.line(img, (cx, hip), (cx + dx, foot), (*trousers, 255), 2 * leg)
            cv2.line(img, (cx + dx, foot), (cx + dx + _px(0.1), foot), (20, 20, 20, 255), leg)
        arm_dx = round(stride * _px(0.18))
        cv2.line(img, (cx, torso_top + _px(0.05)), (cx - arm_dx, _px(0.9)), (*skin, 255),
                 _px(0.07))
    else:
        for sgn in (-1, 1):
            x = cx + sgn * _px(0.1)
            cv2.line(img, (x, hip), (x, foot), (*trousers, 255), 2 * leg)
            cv2.rectangle(img, (x - leg, foot - _px(0.04)), (x + leg, foot + _px(0.02)),
                          (20, 20, 20, 255), -1)
            ax = cx + sgn * (half + _px(0.04))
            cv2.line(img, (ax, torso_top + _px(0.05)), (ax, _px(0.9)), (*shirt, 255), _px(0.07))
            cv2.circle(img, (ax, _px(0.92)), _px(0.04), (*skin, 255), -1)
    _shade(img, rng, 4.0)
    return Sprite(img, width_m, height_m)


def bicycle(rng: np.random.Generator, side: bool) -> Sprite:
    """A bicycle with its rider, from the side (1.75 m long) or from behind."""
    width_m, height_m = (1.8, 1.8) if side else (0.7, 1.8)
    img = _canvas(width_m, height_m)
    h, w = img.shape[:2]
    frame_c, tyre = (40, 40, 180), (20, 20, 20)
    shirt = SHIRTS[int(rng.integers(len(SHIRTS)))]
    r = _px(0.34)
    ground = h - 2
    if side:
        rear, front = (_px(0.4), ground - r), (w - _px(0.4), ground - r)
        for c in (rear, front):
            cv2.circle(img, c, r, (*tyre, 255), _px(0.04))
            for k in range(12):
                angle = k * np.pi / 6
                tip = (round(c[0] + r * np.cos(angle)), round(c[1] + r * np.sin(angle)))
                cv2.line(img, c, tip, (170, 170, 170, 255), 1)
        crank = ((rear[0] + front[0]) // 2 - _px(0.1), ground - r + _px(0.05))
        seat = (crank[0] - _px(0.12), ground - _px(0.95))
        bar = (front[0] - _px(0.12), ground - _px(1.0))
        for p0, p1 in ((rear, crank), (crank, seat), (seat, rear), (seat, bar), (bar, front),
                       (bar, crank)):
            cv2.line(img, p0, p1, (*frame_c, 255), _px(0.035))
        hip = (seat[0], seat[1] - _px(0.05))
        shoulder = (hip[0] + _px(0.3), hip[1] - _px(0.5))
        cv2.line(img, hip, shoulder, (*shirt, 255), _px(0.2))
        cv2.line(img, shoulder, bar, (*shirt, 255), _px(0.07))
        cv2.line(img, hip, crank, (70, 50, 40, 255), _px(0.12))
        cv2.circle(img, (shoulder[0] + _px(0.05), shoulder[1] - _px(0.14)), _px(0.11),
                   (120, 150, 200, 255), -1)
    else:
        cx = w // 2
        cv2.rectangle(img, (cx - _px(0.025), ground - 2 * r), (cx + _px(0.025), ground),
                      (*tyre, 255), -1)
        cv2.rectangle(img, (cx - _px(0.3), ground - _px(1.0)), (cx + _px(0.3),
                      ground - _px(0.97)), (*frame_c, 255), -1)   # handlebar
        cv2.rectangle(img, (cx - _px(0.06), ground - _px(0.3)), (cx + _px(0.06),
                      ground - _px(0.25)), (30, 30, 200, 255), -1)   # rear reflector
        cv2.rectangle(img, (cx - _px(0.2), ground - _px(1.5)), (cx + _px(0.2),
                      ground - _px(0.9)), (*shirt, 255), -1)
        for sgn in (-1, 1):
            cv2.line(img, (cx + sgn * _px(0.1), ground - _px(0.9)),
                     (cx + sgn * _px(0.12), ground - _px(0.45)), (70, 50, 40, 255), _px(0.1))
        cv2.circle(img, (cx, ground - _px(1.62)), _px(0.11), (30, 40, 60, 255), -1)
    _shade(img, rng, 4.0)
    return Sprite(img, width_m, height_m)


# -- the roadside and the false targets ------------------------------------------------------

SCENERY_RES_M = 0.04        # roadside texture: metres per texel
SCENERY_TILE_M = 48.0       # the roadside repeats every SCENERY_TILE_M along x
SCENERY_HEIGHT_M = 7.0      # hedges, trees and house fronts up to this height
BACKDROP_HEIGHT_M = 24.0    # the far tree line and buildings straight ahead


def _speckle(rng: np.random.Generator, shape: tuple[int, int], density: float,
             amplitude: float) -> np.ndarray:
    """Sparse single-texel spots of +-amplitude (stones in asphalt, leaves, gravel)."""
    spots = (rng.random(shape, dtype=np.float32) < density).astype(np.float32)
    sign = np.where(rng.random(shape, dtype=np.float32) < 0.5, np.float32(-1.0),
                    np.float32(1.0))
    return np.asarray(cv2.GaussianBlur(spots * sign, (0, 0), 0.7) * amplitude * 3.0,
                      np.float32)


def road_wear(rng: np.random.Generator, img: np.ndarray) -> None:
    """What real asphalt shows a camera, in place on a road texture (rows along x,
    columns along y): aggregate stones, cracks, repair patches and tar seams, with the
    contrast that gives real road images their edges. Applied in bands of rows:
    whole-tile float temporaries would cost the camera process tens of MB at start."""
    rows, cols = img.shape[:2]
    offset = np.zeros((rows, cols), np.int16)
    for _ in range(rows * cols // 30_000):          # repair patches, sharp-edged
        h, w = int(rng.integers(20, 120)), int(rng.integers(20, 120))
        r0, c0 = int(rng.integers(0, rows - h)), int(rng.integers(0, cols - w))
        offset[r0:r0 + h, c0:c0 + w] += int(rng.uniform(-28, 18))
    crack = np.zeros((rows, cols), np.uint8)
    for _ in range(rows * cols // 6_000):           # cracks and tar seams
        p = np.array([rng.integers(0, cols), rng.integers(0, rows)], np.float64)
        angle = rng.uniform(0, 2 * np.pi)
        pts = [p.copy()]
        for _ in range(int(rng.integers(3, 10))):
            angle += rng.normal(0, 0.6)
            p = p + rng.uniform(5, 25) * np.array([np.cos(angle), np.sin(angle)])
            pts.append(p.copy())
        cv2.polylines(crack, [np.array(pts, np.int32)], False, 1, int(rng.integers(1, 5)))
    offset -= crack.astype(np.int16) * 45
    del crack
    for r0 in range(0, rows, 200):
        r1 = min(r0 + 200, rows)
        f = img[r0:r1].astype(np.float32)
        f += (_speckle(rng, (r1 - r0, cols), 0.08, 30.0) + offset[r0:r1])[:, :, None]
        img[r0:r1] = np.clip(f, 0, 255).astype(np.uint8)


def roadside_texture(rng: np.random.Generator) -> np.ndarray:
    """BGR, rows along x (SCENERY_TILE_M), columns up from the ground (column 0) to
    SCENERY_HEIGHT_M: a roadside of hedges, trees, fences and house fronts."""
    rows = round(SCENERY_TILE_M / SCENERY_RES_M)
    cols = round(SCENERY_HEIGHT_M / SCENERY_RES_M)
    img = np.empty((rows, cols, 3), np.float32)
    img[:] = (55, 105, 70)
    x = 0
    while x < rows:
        n = int(rng.integers(100, 300))             # 4-12 m of one kind
        kind = int(rng.integers(0, 3))
        seg = img[x:x + n]
        if kind == 0:                                # hedge and trees: foliage
            seg[:] = (40 + rng.integers(0, 20), 95 + rng.integers(0, 30), 60)
        elif kind == 1:                              # a house front with windows
            wall = rng.integers(120, 210, 3).astype(np.float32)
            seg[:] = wall
            for r in range(int(rng.integers(3, 10)), seg.shape[0] - 20, 30):
                for c in (25, 80, 135):
                    if c + 25 < cols:
                        seg[r:r + 18, c:c + 25] = (70, 60, 55)
                        seg[r:r + 18, c + 12] = (180, 180, 180)
            seg[:, 160:] = (60, 60, 130)             # the roof
        else:                                        # a fence in front of bushes
            seg[:] = (45, 110, 75)
            seg[::6, :40] = (90, 110, 130)
            seg[:, 20:22] = (90, 110, 130)
            seg[:, 38:40] = (90, 110, 130)
        x += n
    img += _blur_noise(rng, (rows, cols), 1.5, 14.0)[:, :, None]
    img += _speckle(rng, (rows, cols), 0.12, 40.0)[:, :, None]
    return np.clip(img, 0, 255).astype(np.uint8)


def backdrop_texture(rng: np.random.Generator, width_m: float, res_m: float) -> np.ndarray:
    """BGRA, columns across the view from left (+y) to right, rows from the top
    (BACKDROP_HEIGHT_M) down to the ground: a distant tree line and buildings whose tops
    stand against the sky (alpha 0 above them)."""
    cols = round(width_m / res_m)
    rows = round(BACKDROP_HEIGHT_M / res_m)
    img = np.zeros((rows, cols, 4), np.float32)
    top = np.empty(cols)
    c = 0
    while c < cols:
        n = int(rng.integers(8, 60))
        top[c:c + n] = rng.uniform(4.0, 20.0)
        c += n
    top_m = np.asarray(cv2.GaussianBlur(top.reshape(1, -1).astype(np.float32), (0, 0), 1.0),
                       np.float64).ravel()
    height_of_row = BACKDROP_HEIGHT_M - (np.arange(rows) + 0.5) * res_m
    solid = height_of_row[:, None] <= top_m[None, :]
    img[..., 0] = 70
    img[..., 1] = 100
    img[..., 2] = 90
    img[..., :3] += _blur_noise(rng, (rows, cols), 1.0, 22.0)[:, :, None]
    img[..., :3] += _speckle(rng, (rows, cols), 0.15, 45.0)[:, :, None]
    img[..., 3] = np.where(solid, 255, 0)
    return np.clip(img, 0, 255).astype(np.uint8)


def manhole(rng: np.random.Generator, size_m: float) -> Sprite:
    """A cast-iron manhole cover (or a steel plate) seen from above: a dark disc with its
    raised grid, flat on the road."""
    img = _canvas(size_m, size_m)
    h, w = img.shape[:2]
    centre, r = (w // 2, h // 2), min(w, h) // 2 - 1
    cv2.circle(img, centre, r, (52, 54, 58, 255), -1)
    grid = np.zeros((h, w), np.uint8)
    for k in range(-r, r, _px(0.05)):
        cv2.line(grid, (centre[0] + k, 0), (centre[0] + k, h), 255, 2)
        cv2.line(grid, (0, centre[1] + k), (w, centre[1] + k), 255, 2)
    inside = np.zeros((h, w), np.uint8)
    cv2.circle(inside, centre, r - _px(0.04), 255, -1)
    img[(grid > 0) & (inside > 0), :3] = (80, 82, 86)
    cv2.circle(img, centre, r, (30, 30, 32, 255), _px(0.03))
    _shade(img, rng, 5.0)
    return Sprite(img, size_m, size_m)


def sign_board(rng: np.random.Generator, width_m: float, height_m: float) -> Sprite:
    """An overhead direction sign: green board, white border, white lettering."""
    img = _canvas(width_m, height_m)
    h, w = img.shape[:2]
    img[:] = (60, 110, 20, 255)
    cv2.rectangle(img, (6, 6), (w - 7, h - 7), (235, 235, 235, 255), 6)
    for k, text in enumerate(("CITY CENTRE 4", "AIRPORT  12")):
        cv2.putText(img, text, (round(0.06 * w), round((0.42 + 0.38 * k) * h)),
                    cv2.FONT_HERSHEY_SIMPLEX, h / 170.0, (235, 235, 235, 255), max(h // 40, 2))
    _shade(img, rng, 4.0)
    return Sprite(img, width_m, height_m)


def guard_rail(rng: np.random.Generator, length_m: float, height_m: float) -> Sprite:
    """A W-beam guard rail's face on its posts (transparent between the posts)."""
    img = _canvas(length_m, height_m)
    w = img.shape[1]
    beam = _px(0.3)
    img[:beam] = (165, 168, 170, 255)
    for k in range(3):                               # the W profile's folds
        y = round((k + 0.5) * beam / 3)
        img[y:y + 4, :, :3] = (110, 112, 115)
    for x in range(_px(0.3), w, _px(2.0)):           # a post every 2 m
        img[beam:, x:x + _px(0.12)] = (70, 72, 75, 255)
    _shade(img, rng, 5.0)
    return Sprite(img, length_m, height_m)
