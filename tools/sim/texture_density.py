"""How many edges the simulated camera's frames have where nothing stands, measured with
the project's own `edge_density` verifier: the paper's ROI construction at its pixel
scale (a column 1.08 m wide, 0-2.2 m high, at the track's range, 22 px padding) on
rendered frames as fusion receives them (JPEG q80, decoded to grey on the project's one
path). Real driving images give background ROIs a median density of about 0.16 (issue
18, KITTI); the roadside scenery of tools/sim/render.py is made to match it.

    python -m aeb_radar_camera.tools.sim.texture_density            # both renderings, side by side

A SIMULATION measurement: the frames are rendered.
"""

import argparse
import sys
from dataclasses import dataclass

import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.imaging import decode_gray, encode_jpeg
from aeb_radar_camera.common.resources import EXAMPLE_CALIBRATION
from aeb_radar_camera.services.fusion.roi import ColumnGeometry, ColumnProjector
from aeb_radar_camera.services.fusion.verifiers import Observation, create
from aeb_radar_camera.tools.messages import ObjectKind
from aeb_radar_camera.tools.sim.render import Renderer
from aeb_radar_camera.tools.sim.scenario import DEFAULT_SIZE
from aeb_radar_camera.tools.sim.world import Body

PAPER_COLUMN = ColumnGeometry(height_m=2.2, half_width_m=0.54, padding_px=22)
RANGES_M = (4.0, 6.0, 8.0, 10.0, 13.0, 16.0, 20.0, 25.0)
LATERAL_M = (-6.0, -4.0, -2.0, 0.0, 2.0, 4.0, 6.0)
EGO_X_M = (0.0, 7.3, 15.1, 23.9)
OBSTACLES = (ObjectKind.CAR, ObjectKind.BOX, ObjectKind.PEDESTRIAN, ObjectKind.BICYCLE)


@dataclass(frozen=True)
class Survey:
    background: np.ndarray        # densities of empty ROIs
    obstacles: np.ndarray         # densities of ROIs at an obstacle
    obstacle_passed: float        # share of obstacle ROIs the verifier passes
    background_passed: float


def _densities(renderer: Renderer, projector: ColumnProjector, bodies: list[Body],
               ego_x: float, xy: list[tuple[float, float]]) -> list[tuple[float, bool]]:
    verifier = create("edge_density")
    gray = decode_gray(encode_jpeg(renderer.render(bodies, ego_x), 80))
    out = []
    for (x, y), boxes in zip(xy, projector.boxes(np.array(xy)), strict=True):
        if boxes is None:
            continue
        roi, column = boxes
        result = verifier.verify(Observation(gray, roi, column, float(np.hypot(x, y))))
        out.append((result.score, result.verified))
    return out


def survey(renderer: Renderer) -> Survey:
    """Background ROIs on the empty road at every range and lateral offset for a few ego
    positions; obstacle ROIs at each obstacle kind in the lane at every range."""
    projector = ColumnProjector(renderer.cal, PAPER_COLUMN)
    back: list[tuple[float, bool]] = []
    for ego_x in EGO_X_M:
        xy = [(r, y) for r in RANGES_M for y in LATERAL_M]
        back += _densities(renderer, projector, [], ego_x, xy)
    obst: list[tuple[float, bool]] = []
    for i, kind in enumerate(OBSTACLES):
        length, width, height = DEFAULT_SIZE[kind]
        for r in RANGES_M:
            ego_x = EGO_X_M[i % len(EGO_X_M)]
            body = Body(i, kind, ego_x + r + length / 2, 0.0, 0.0, length, width, height,
                        0.0, 0.0)
            obst += _densities(renderer, projector, [body], ego_x, [(r, 0.0)])
    b = np.array([d for d, _ in back])
    o = np.array([d for d, _ in obst])
    return Survey(b, o, float(np.mean([v for _, v in obst])),
                  float(np.mean([v for _, v in back])))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m aeb_radar_camera.tools.sim.texture_density",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=3)
    args = parser.parse_args(argv)
    cal = Calibration.load(EXAMPLE_CALIBRATION)
    print(f"edge_density (Canny 40/120, tau 0.025) on the paper's ROIs, JPEG q80; "
          f"{len(RANGES_M)} ranges {RANGES_M[0]:g}-{RANGES_M[-1]:g} m")
    for roadside in (False, True):
        s = survey(Renderer(cal, seed=args.seed, roadside=roadside))
        name = "roadside (closed loop)" if roadside else "plain (test scenes)"
        q = np.percentile(s.background, [25, 50, 75])
        print(f"{name:<24} background n={len(s.background)} median {q[1]:.3f} "
              f"(IQR {q[0]:.3f}-{q[2]:.3f}), passed {s.background_passed:.0%}; obstacles "
              f"n={len(s.obstacles)} median {np.median(s.obstacles):.3f}, min "
              f"{s.obstacles.min():.3f}, passed {s.obstacle_passed:.0%}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
