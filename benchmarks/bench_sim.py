"""The simulator's own costs (SIMULATION): a rendered frame by day, at dusk, at night, in
rain and on a bend, and a world step, each beside its baseline in the same run. The
lockstep closed loop renders frames on demand and steps the world every tick, so its
speed follows these; the real-time camera has 33 ms a frame at 30 fps.

- render: ms of CPU per 848x480 frame with the roadside (the closed loop's camera),
  beside the plain road of the still test scenes; with its depth; on a bend once the ego
  is in it (the view is the same at every station: built once) and while it approaches
  one (the view's geometry built again every 0.5 m: every third frame at 20 km/h, every
  frame at 60 km/h);
- world: us per step of a case's world (a pedestrian crossing; the guard rail along a
  bend, 13 objects), beside a single car on a straight road; the tick the real-time
  runner does (step, ground truth) and a radar cycle of the model.

    python -m benchmarks.bench_sim [--quick]
"""

import time
from collections.abc import Callable
from pathlib import Path

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.resources import EXAMPLE_CALIBRATION
from aeb_radar_camera.tools.messages import Lighting, ObjectKind, RoadGeometry
from aeb_radar_camera.tools.sim.families import case_of
from aeb_radar_camera.tools.sim.radar_model import RadarModel
from aeb_radar_camera.tools.sim.render import Renderer
from aeb_radar_camera.tools.sim.road import Road, RoadView
from aeb_radar_camera.tools.sim.scenario import (
    CameraLook,
    EgoSpec,
    Scenario,
    ScenarioKind,
    SceneObject,
    find_scenario,
    load_scenario,
)
from aeb_radar_camera.tools.sim.world import Body, World
from benchmarks.figures import Figure, section_main

BODIES = [Body(0, ObjectKind.CAR, 30.0, 0.4, 0.0, 4.4, 1.8, 1.5, 0.0, 0.0),
          Body(1, ObjectKind.PEDESTRIAN, 16.0, -2.0, 90.0, 0.35, 0.55, 1.75, 0.0, 1.4)]


def per_call(fn: Callable[[int], object], n: int) -> float:
    """Mean time of `fn(i)` over n calls, in ms (after one warm-up call): the mean, as
    the occasional rebuilt view belongs to the cost."""
    fn(0)
    t = time.perf_counter()
    for i in range(1, n + 1):
        fn(i)
    return (time.perf_counter() - t) * 1e3 / n


def _frames(renderer: Renderer, lighting: Lighting, depth: bool = False,
            road: Callable[[int], RoadView | None] = lambda i: None) -> Callable[[int], object]:
    """A frame of BODIES per call, the ego 0.1 m further each time (or along `road`)."""
    def frame(i: int) -> object:
        renderer.set_look(CameraLook(), lighting)
        view = road(i)
        ego = 0.1 * i if view is None else 0.0
        if depth:
            return renderer.render_rgbd(BODIES, ego, millimetres=True, road=view)
        return renderer.render(BODIES, ego, road=view)
    return frame


def render_figures(quick: bool) -> list[Figure]:
    n = 10 if quick else 60
    cal = Calibration.load(EXAMPLE_CALIBRATION)
    plain = Renderer(cal, seed=3, roadside=False)
    scene = Renderer(cal, seed=3)
    bend = Road(RoadGeometry(curve_start_m=20.0, radius_m=50.0))

    def in_bend(i: int) -> RoadView:
        return RoadView(bend, 30.0 + 0.2 * i)

    def approaching(i: int) -> RoadView:       # at 20 km/h and 30 fps: 0.19 m a frame
        return RoadView(bend, 20 / 3.6 / 30 * i)

    def approaching_fast(i: int) -> RoadView:  # at 60 km/h: a new view every frame
        return RoadView(bend, 60 / 3.6 / 30 * (i % 30))

    base = per_call(_frames(plain, Lighting.DAY), n)
    cases = [("day", _frames(scene, Lighting.DAY)),
             ("day with depth", _frames(scene, Lighting.DAY, depth=True)),
             *((light.value, _frames(scene, light))
               for light in (Lighting.DUSK, Lighting.NIGHT, Lighting.RAIN)),
             ("bend, in it", _frames(scene, Lighting.DAY, road=in_bend)),
             ("bend, in it, with depth", _frames(scene, Lighting.DAY, True, in_bend)),
             ("bend, approaching at 20 km/h", _frames(scene, Lighting.DAY, road=approaching)),
             ("bend, approaching at 60 km/h", _frames(scene, Lighting.DAY,
                                                       road=approaching_fast))]
    out = []
    for name, fn in cases:
        ms = per_call(fn, n)
        out.append(Figure("sim render", f"frame, {name}", round(ms, 2), "ms",
                          baseline="plain road (still scenes)", baseline_value=round(base, 2),
                          target="< 33 ms (30 fps, one core)", target_met=ms < 33.0))
    return out


class _Running:
    """A scenario's world driven unbraked, started again when its run is over (a
    collision stops a world)."""

    def __init__(self, sc: Scenario) -> None:
        self.sc = sc
        self.world = World(sc)

    def live(self) -> World:
        w = self.world
        if w.collision is not None or w.t_s >= self.sc.duration_s or (
                self.sc.kind is ScenarioKind.NO_THREAT and w.passed_everything()):
            self.world = World(self.sc)
        return self.world

    def step(self, i: int) -> None:
        self.live().step(0.005, 0.0)

    def tick(self, i: int) -> None:
        """What the real-time runner does a tick: step, then the ground truth."""
        w = self.live()
        w.step(0.005, 0.0)
        w.threat()
        w.in_path_gap()
        w.false_target_gap()


def world_figures(quick: bool) -> list[Figure]:
    n = 500 if quick else 4000
    one_car = Scenario(name="one car", kind=ScenarioKind.THREAT, ego=EgoSpec(speed_kph=30.0),
                       object=(SceneObject(ObjectKind.CAR, 400.0),), duration_s=120.0)
    base = per_call(_Running(one_car).step, n) * 1e3
    crossing = case_of("CPNA-25", 40.0, light="day").scenario()
    rail = load_scenario(find_scenario("no_threat_guard_rail_bend_20kph"))
    out = []
    for label, sc in (("pedestrian crossing (CPNA-25)", crossing),
                      ("guard rail along a bend (13 objects)", rail)):
        running = _Running(sc)
        model = RadarModel(sc.radar_look(), sc.seed)

        def radar(i: int, running: _Running = running, model: RadarModel = model) -> None:
            w = running.live()
            w.step(0.075, 0.0)
            model.cycle(w.vehicle_bodies(), 0.0, w.ego.speed_mps, w.yaw_rate_dps())

        for what, fn, reps in (("step", running.step, n), ("tick (step + ground truth)",
                                                            running.tick, n // 2),
                               ("radar cycle (step + model)", radar, n // 8)):
            us = per_call(fn, reps) * 1e3
            out.append(Figure("sim world", f"{what}, {label}", round(us, 1), "us",
                              baseline="step, one car, straight road",
                              baseline_value=round(base, 1)))
    return out


def run(quick: bool, out_dir: Path) -> list[Figure]:
    figures = render_figures(quick) + world_figures(quick)
    for f in figures:
        print(f"{f.group:<10} {f.name:<58} {f.value:>8.2f} {f.unit:<3} "
              f"(baseline {f.baseline}: {f.baseline_value})")
    return figures


def main(argv: list[str] | None = None) -> int:
    return section_main("benchmarks.bench_sim", __doc__, run, argv)


if __name__ == "__main__":
    raise SystemExit(main())
