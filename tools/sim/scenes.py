"""SIMULATION: still road scenes for testing and benchmarking the gate, drawn by the
simulator's renderer (tools/sim/render.py) with obstacles at radar-frame positions.

These images are not camera data; they give tests and benchmarks real-looking pixels
with known ground truth: an obstacle or an empty road at a track's position, by day or
at night (headlights, street lamps, oncoming headlights, sensor noise). They use the
plain rendering (smooth road, open sky: few edges where nothing stands), not the
closed loop's roadside scenery whose background has the edge density of real images.
"""

from dataclasses import dataclass

import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.imaging import encode_jpeg
from aeb_radar_camera.tools.messages import ObjectKind
from aeb_radar_camera.tools.sim.render import Light, Renderer
from aeb_radar_camera.tools.sim.scenario import DEFAULT_SIZE, CameraLook
from aeb_radar_camera.tools.sim.world import Body

# Light at night without the ego's headlights, relative to day.
NIGHT_AMBIENT = 0.12


@dataclass(frozen=True)
class Obstacle:
    """An obstacle standing on the ground, its face nearest the ego at (x_m, y_m) in the
    radar frame (where the radar would report it). `size_m`: length, width, height;
    None for the kind's usual size."""

    x_m: float
    y_m: float
    kind: ObjectKind = ObjectKind.BOX
    size_m: tuple[float, float, float] | None = None

    def body(self, index: int) -> Body:
        length, width, height = self.size_m or DEFAULT_SIZE[self.kind]
        return Body(index, self.kind, self.x_m + length / 2, self.y_m, 0.0, length, width,
                    height, 0.0, 0.0)


@dataclass(frozen=True)
class Scene:
    obstacles: tuple[Obstacle, ...] = ()
    night: bool = False
    lights: tuple[Light, ...] = ()
    noise_sigma: float = 0.0       # sensor noise (grey levels)
    seed: int = 0                  # the objects' textures and the noise


def render(cal: Calibration, scene: Scene) -> np.ndarray:
    """A BGR uint8 frame of the scene (cal.width x cal.height). The same scene gives the
    same pixels on every call."""
    renderer = _renderer(cal)
    renderer.set_look(CameraLook(brightness=NIGHT_AMBIENT if scene.night else 1.0,
                                 noise=scene.noise_sigma))
    renderer.new_scene(scene.seed)
    bodies = [ob.body(i) for i, ob in enumerate(scene.obstacles)]
    return renderer.render(bodies, 0.0, scene.lights, headlights=scene.night)


_RENDERERS: dict[bytes, Renderer] = {}


def _renderer(cal: Calibration) -> Renderer:
    """One renderer per calibration: building one takes most of a second."""
    key = b"".join(np.ascontiguousarray(a, np.float64).tobytes()
                   for a in (cal.k, cal.dist, cal.r, cal.t, [cal.width, cal.height]))
    if key not in _RENDERERS:
        _RENDERERS[key] = Renderer(cal, roadside=False)
    return _RENDERERS[key]


@dataclass(frozen=True)
class LabelledFrame:
    """One frame (JPEG, as the camera would publish it) and a track position at which an
    obstacle stands (`obstacle` True) or the road is empty."""

    jpeg: bytes
    track_xy: tuple[float, float]
    obstacle: bool
    night: bool
    noise_sigma: float
    kind: str


_KINDS = (ObjectKind.BOX, ObjectKind.PEDESTRIAN, ObjectKind.CAR)


def labelled_frames(cal: Calibration, n: int, seed: int = 0, night_share: float = 0.5,
                    quality: int = 80) -> list[LabelledFrame]:
    """`n` frames, half with an obstacle at the track, half with an empty road there.

    Night frames get 1-3 oncoming headlights and 0-2 street lamps at random places ahead,
    and sensor noise of 0-6 grey levels; day frames 0-2 grey levels.
    """
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
        kind = _KINDS[int(rng.integers(len(_KINDS)))]
        obstacles = (Obstacle(x, y, kind),) if obstacle else ()
        scene = Scene(obstacles=obstacles, night=night, lights=tuple(lights),
                      noise_sigma=noise, seed=seed * 100_003 + i)
        out.append(LabelledFrame(encode_jpeg(render(cal, scene), quality), (x, y), obstacle,
                                 night, noise, kind.value if obstacle else "road"))
    return out
