"""The simulator's camera: a synthetic-source plugin of the camera service that renders
the simulated world. A SIMULATION (the real sources are RealSense, OpenCV, folders).

Camera config::

    [camera.source]
    kind = "synthetic"
    factory = "aeb_radar_camera.tools.sim.camera_source:make_source"

The source follows `sim/world` (published by the simulator) on the camera's own bus,
extrapolates the latest world state to each frame's capture time (objects at their
velocities, the ego with its acceleration) and renders it with the camera's calibration,
so the frame matches what fusion projects radar tracks into. Each frame carries its
aligned depth (uint16 mm, 0 = no return), rendered from the same geometry: the camera
service publishes it as DepthFrame beside the JPEG (`[camera.depth]`). The depth is the
exact geometry unless the option `depth_noise` applies the D435's error model
(common/depth_error.py: about 21 ms a full frame, too slow for 30 fps beside the
rendering). Option `depth = false`: colour only, as a camera without depth. Before the
first world state arrives it renders the empty road (so the camera is up before the simulator);
once the simulator has been seen, a world older than `stale_after_s` is a camera failure
(`SourceError`): fusion then sees no fresh frames, as with a real camera that stopped.
"""

import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.clock import wall_ns
from aeb_radar_camera.common.depth_error import D435Noise
from aeb_radar_camera.common.depth_image import to_units
from aeb_radar_camera.services.camera.plugin import PluginContext
from aeb_radar_camera.services.camera.source import (
    Frame,
    FrameSource,
    Pacer,
    SourceConfigError,
    SourceError,
)
from aeb_radar_camera.tools.keys import SIM_WORLD
from aeb_radar_camera.tools.messages import SimWorld
from aeb_radar_camera.tools.sim.render import Renderer
from aeb_radar_camera.tools.sim.road import Road, RoadView
from aeb_radar_camera.tools.sim.scenario import CameraLook
from aeb_radar_camera.tools.sim.world import Body

MAX_EXTRAPOLATION_S = 0.25
PLUGIN = f"{__name__}:make_source"    # as a camera config names it


@dataclass(frozen=True)
class SceneView:
    """What the camera sees at one instant: the bodies in the frame along the ego's
    heading with the radar at (`ego_x_m`, 0) (the vehicle frame shifted by the ego's
    station: on a straight road the world frame), and where on the road the ego is."""

    bodies: list[Body]
    ego_x_m: float
    road: RoadView


def scene_at(world: SimWorld, stamp_ns: int) -> SceneView:
    """The world extrapolated to `stamp_ns` (at most 0.25 s ahead): objects at their
    velocities, the ego along the road with its acceleration."""
    dt = min(max((stamp_ns - world.header.stamp_ns) / 1e9, 0.0), MAX_EXTRAPOLATION_S)
    v = world.ego_speed_mps
    a = world.ego_accel_mps2
    stops = a < 0 and v + a * dt < 0      # within dt
    ds = v * v / (-2 * a) if stops else v * dt + 0.5 * a * dt * dt
    station = world.ego_station() + ds
    view = RoadView(Road(world.road), station, world.ego_d_m)
    pose = view.pose
    bodies = [Body.of(o).shifted(dt).seen_from(pose, station) for o in world.objects]
    return SceneView(bodies, station, view)


def bodies_at(world: SimWorld, stamp_ns: int) -> tuple[list[Body], float]:
    """`scene_at`'s bodies and the ego's station (see SceneView for their frame)."""
    view = scene_at(world, stamp_ns)
    return view.bodies, view.ego_x_m


class SimCameraSource(FrameSource):
    """Renders `sim/world` at a fixed rate. A SIMULATION."""

    kind = "synthetic"

    def __init__(self, calibration: Calibration, fps: float,
                 subscribe: Callable[[Callable[[SimWorld, str], None]], object] | None,
                 stale_after_s: float = 1.0,
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep,
                 wall_clock: Callable[[], int] = wall_ns,
                 depth: bool = True, depth_noise: bool = False) -> None:
        super().__init__()
        self.renderer = Renderer(calibration)
        self.depth = depth
        self.depth_noise = D435Noise() if depth_noise else None
        self._noise_rng = np.random.default_rng(0)
        self.fps = fps
        self.stale_after_s = stale_after_s
        self._pacer = Pacer(fps, clock, sleep)
        self._clock = clock
        self._wall = wall_clock
        self._lock = threading.Lock()
        self._world: SimWorld | None = None
        self._world_at = 0.0
        self._scene = (-1, -1)
        self._subscription = subscribe(self.on_world) if subscribe is not None else None

    def describe(self) -> str:
        depth = ("" if not self.depth else
                 ", with depth (D435 noise)" if self.depth_noise else ", with exact depth")
        return (f"simulated camera {self.renderer.width}x{self.renderer.height} at "
                f"{self.fps:g} fps{depth}, rendering sim/world (simulation)")

    def on_world(self, world: SimWorld, key: str = "") -> None:
        with self._lock:
            if self._world is None or world.header.stamp_ns >= self._world.header.stamp_ns:
                self._world = world
                self._world_at = self._clock()

    def open(self) -> None:
        self._pacer.reset()

    def frame_at(self, stamp_ns: int) -> np.ndarray:
        """The rendered frame for the latest world at `stamp_ns`. Raises SourceError when
        the simulator went silent."""
        return self._scene_at(stamp_ns, with_depth=False)[0]

    def frame_and_depth_at(self, stamp_ns: int) -> tuple[np.ndarray, np.ndarray | None]:
        """The frame and its aligned depth (uint16 mm; None without depth). Raises
        SourceError when the simulator went silent."""
        if not self.depth:
            return self._scene_at(stamp_ns, with_depth=False)
        if self.depth_noise is None:
            return self._scene_at(stamp_ns, with_depth=True, millimetres=True)
        image, depth_m = self._scene_at(stamp_ns, with_depth=True)
        assert depth_m is not None
        return image, to_units(self.depth_noise.apply(depth_m, self._noise_rng))

    def _scene_at(self, stamp_ns: int, with_depth: bool, millimetres: bool = False
                  ) -> tuple[np.ndarray, np.ndarray | None]:
        with self._lock:
            world, seen_at = self._world, self._world_at
        bodies: list[Body] = []
        ego_x = 0.0
        if world is not None:
            age = self._clock() - seen_at
            if age > self.stale_after_s:
                raise SourceError(f"no simulator world for {age:.1f} s (is the simulator "
                                  "running?)")
            if (world.run, world.seed) != self._scene:
                self._scene = (world.run, world.seed)
                self.renderer.new_scene(world.seed)
                self._noise_rng = np.random.default_rng((world.seed, 2))
            self.renderer.set_look(CameraLook(brightness=world.brightness, noise=world.noise),
                                   world.lighting)
            view = scene_at(world, stamp_ns)
            bodies, ego_x, road = view.bodies, view.ego_x_m, view.road
        else:
            road = None
        if with_depth:
            return self.renderer.render_rgbd(bodies, ego_x, millimetres, road=road)
        return self.renderer.render(bodies, ego_x, road=road), None

    def read(self) -> Frame:
        self._pacer.wait()
        stamp = self._wall()
        image, depth = self.frame_and_depth_at(stamp)
        return Frame(image=image, stamp_ns=stamp, depth=depth)


def make_source(context: PluginContext) -> SimCameraSource:
    """The camera plugin factory. Options: `stale_after_s` (default 1.0), `depth`
    (default true: aligned depth with every frame), `depth_noise` (default false: the
    exact geometry; true: the D435's error model).

    Raises SourceConfigError without a calibration or a bus (it must run inside the
    camera service), or for unknown options.
    """
    unknown = set(context.options) - {"stale_after_s", "depth", "depth_noise"}
    if unknown:
        raise SourceConfigError(f"{PLUGIN}: unknown options {sorted(unknown)}")
    if context.calibration is None:
        raise SourceConfigError(f"{PLUGIN} needs the camera's calibration")
    bus = context.bus
    if bus is None:
        raise SourceConfigError(f"{PLUGIN} needs the camera's bus "
                                "(it follows sim/world)")
    if (context.calibration.width, context.calibration.height) != (context.width,
                                                                    context.height):
        raise SourceConfigError("calibration size differs from the camera's frame size")
    return SimCameraSource(
        context.calibration, context.fps,
        lambda cb: bus.subscribe(SIM_WORLD, cb),
        stale_after_s=float(context.options.get("stale_after_s", 1.0)),
        depth=_flag(context.options, "depth", True),
        depth_noise=_flag(context.options, "depth_noise", False))


def _flag(options: Mapping[str, object], name: str, default: bool) -> bool:
    """A boolean option. Raises SourceConfigError for anything but true or false."""
    value = options.get(name, default)
    if not isinstance(value, bool):
        raise SourceConfigError(f"{PLUGIN}: option {name} must be true or "
                                f"false, got {value!r}")
    return value
