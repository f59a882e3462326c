"""Each verifier on the simulator's own frames, without the closed loop's timing: a
scenario driven without braking, every radar cycle's in-path returns at 3-25 m (the
decision's window, within LATERAL_M of the path: crossing targets before they enter it)
checked on the frame and depth rendered at that instant, the depth decimated and
restored as the camera and fusion do. Prints, per scenario and verifier, the share of
those returns (ghosts left out) the verifier passes: on an obstacle (a threat, a car
parked beside the path) every one should pass, on a false target none.

    python -m aeb_radar_camera.tools.sim.verifier_probe                    # the demo's scenarios
    python -m aeb_radar_camera.tools.sim.verifier_probe --scenarios no_threat_manhole_30kph \
        --verifiers depth

A SIMULATION measurement (rendered frames, the radar model's returns).
"""

import argparse
import sys

import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.clock import wall_ns
from aeb_radar_camera.common.depth_image import encode_depth
from aeb_radar_camera.common.imaging import decode_gray, encode_jpeg
from aeb_radar_camera.common.messages import DepthFrame, Header, encode
from aeb_radar_camera.common.resources import EXAMPLE_CALIBRATION
from aeb_radar_camera.services.fusion.frames import decode_depth_frame
from aeb_radar_camera.services.fusion.roi import ColumnGeometry, ColumnProjector
from aeb_radar_camera.services.fusion.verifiers import Observation, available, create
from aeb_radar_camera.tools.sim.radar_model import RadarModel
from aeb_radar_camera.tools.sim.render import Renderer
from aeb_radar_camera.tools.sim.road import RoadView
from aeb_radar_camera.tools.sim.scenario import DEMO_SCENARIOS, Scenario, pick_scenarios
from aeb_radar_camera.tools.sim.world import World

LATERAL_M = 4.0             # the path's 1.2 m and crossing targets on their way in
RADAR_PERIOD_S = 0.074
DECIMATION = 2              # the camera's default [camera.depth] decimation
DEPLOYED_COLUMN = ColumnGeometry()   # fusion's default ROI (deploy/fusion.toml)


def probe(scenario: Scenario, renderer: Renderer, verifiers: list[str],
          geometry: ColumnGeometry = DEPLOYED_COLUMN, every: int = 1
          ) -> dict[str, tuple[int, int]]:
    """(passed, checked) per verifier over the scenario's returns near the path, on
    every `every`-th radar cycle."""
    cal = renderer.cal
    projector = ColumnProjector(cal, geometry)
    checks = {name: create(name) for name in verifiers}
    counts = {name: [0, 0] for name in verifiers}
    world = World(scenario)
    model = RadarModel(scenario.radar_look(), scenario.seed)
    renderer.new_scene(scenario.seed)
    renderer.set_look(scenario.camera, scenario.lighting)
    cycle = 0
    while world.t_s < scenario.duration_s and not world.passed_everything() and \
            world.collision is None:
        bodies = world.vehicle_bodies()
        returns = [r for r in model.cycle(bodies, 0.0, world.ego.speed_mps, world.yaw_rate_dps())
                   if r.source >= 0 and 3.0 <= r.x_m <= 25.0 and abs(r.y_m) < LATERAL_M]
        cycle += 1
        if returns and cycle % every == 0:
            image, depth_mm = renderer.render_rgbd(bodies, 0.0, millimetres=True,
                                                   road=RoadView(world.road, world.ego.s_m))
            gray = decode_gray(encode_jpeg(image, 80))
            small = np.ascontiguousarray(depth_mm[::DECIMATION, ::DECIMATION])
            msg = DepthFrame(header=Header(0, "probe", wall_ns(), 0), camera="front",
                             width=small.shape[1], height=small.shape[0], codec="zstd",
                             data=encode_depth(small))
            _, depth = decode_depth_frame(encode(msg), cal.width, cal.height)
            xy = np.array([[r.x_m, r.y_m] for r in returns])
            for r, boxes in zip(returns, projector.boxes(xy), strict=True):
                if boxes is None:
                    continue
                obs = Observation(gray, boxes[0], boxes[1], float(np.hypot(r.x_m, r.y_m)),
                                  depth, cal, (r.x_m, r.y_m))
                for name, verifier in checks.items():
                    counts[name][0] += verifier.verify(obs).verified
                    counts[name][1] += 1
        world.step(RADAR_PERIOD_S, 0.0)
    return {name: (p, n) for name, (p, n) in counts.items()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m aeb_radar_camera.tools.sim.verifier_probe",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenarios", default=",".join(DEMO_SCENARIOS),
                        help="comma-separated names or files, or 'all'")
    parser.add_argument("--verifiers", default="",
                        help=f"comma-separated (default: all of {', '.join(available())})")
    args = parser.parse_args(argv)
    names = [v for v in args.verifiers.split(",") if v] or available()
    renderer = Renderer(Calibration.load(EXAMPLE_CALIBRATION))
    print(f"{'scenario':<42} {'kind':<9} " + " ".join(f"{n:>22}" for n in names))
    for sc in pick_scenarios(args.scenarios):
        counts = probe(sc, renderer, names)
        cells = [f"{p:>4}/{n:<4} ({p / n:4.0%})" if n else f"{'-':>22}"
                 for p, n in (counts[name] for name in names)]
        print(f"{sc.name:<42} {sc.kind.value:<9} " + " ".join(f"{c:>22}" for c in cells),
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
