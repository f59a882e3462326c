"""Ground truth of a simulator recording (SIMULATION): its `sim/world` messages say where
every object was, so each radar track is labelled YES when it lies on an obstacle's
footprint (within the radar's noise) and NO otherwise: a ghost (the radar model's
short-lived false returns) or a persistent false target (a plate on the road, an
overhead sign, a guard rail: NO with its kind). Background negatives avoid every
object's image box.
"""

import bisect
import math

import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.messages import DecodeError, decode
from aeb_radar_camera.tools.eval.adapters.paper_rois import Box2D, footprint_distance
from aeb_radar_camera.tools.messages import ObjectKind, SimWorld
from aeb_radar_camera.tools.sim.camera_source import bodies_at

# A track this close to an object's footprint is that object: the simulated radar's
# position noise (0.1-0.15 m) and its split returns on large objects stay well inside.
TRACK_TOLERANCE_M = 1.0


class Truth:
    """The recorded world states in time order."""

    def __init__(self) -> None:
        self._stamps: list[int] = []
        self._worlds: list[SimWorld] = []

    def add(self, payload: bytes, counters: dict[str, int]) -> None:
        try:
            world = decode(payload, SimWorld)
        except DecodeError:
            counters["world_message"] = counters.get("world_message", 0) + 1
            return
        at = bisect.bisect_right(self._stamps, world.header.stamp_ns)
        self._stamps.insert(at, world.header.stamp_ns)
        self._worlds.insert(at, world)

    def world_at(self, stamp_ns: int) -> SimWorld | None:
        """The latest world state at or before `stamp_ns` (None before the first)."""
        at = bisect.bisect_right(self._stamps, stamp_ns)
        return self._worlds[at - 1] if at else None


def _footprints(world: SimWorld, stamp_ns: int) -> list[tuple[str, np.ndarray, float]]:
    """(kind, footprint in the radar frame, height) of every object at `stamp_ns`: the
    objects the camera renders, also in the moments after a run ended (the radar's
    tracks of them coast on; between runs the world has none)."""
    bodies, ego_x = bodies_at(world, stamp_ns)
    return [(b.kind.value, b.corners() - np.array([ego_x, 0.0]), b.z_m + b.height_m)
            for b in bodies]


def label_track(world: SimWorld, stamp_ns: int, x_m: float, y_m: float) -> tuple[str, str]:
    """(YES | NO, the object's kind or "") for a track at (x, y) in the radar frame: NO
    with the kind on a false target (plate, sign, guard rail), NO and "" off every
    object."""
    best, kind = math.inf, ""
    for k, corners, _ in _footprints(world, stamp_ns):
        d = float(footprint_distance(np.array([[x_m, y_m]]), corners)[0])
        if d < best:
            best, kind = d, k
    if best > TRACK_TOLERANCE_M:
        return ("NO", "")
    return ("YES" if ObjectKind(kind).is_obstacle else "NO", kind)


def object_boxes(world: SimWorld, stamp_ns: int, cal: Calibration,
                 margin_px: float = 3.0) -> list[Box2D]:
    """Image boxes of every object at `stamp_ns` (its 3-D box projected, plus a margin)."""
    out: list[Box2D] = []
    for _, corners, height in _footprints(world, stamp_ns):
        pts = np.array([[x, y, z] for x, y in corners for z in (0.0, height)])
        uv, ok = cal.project(pts)
        if not ok.any():
            continue
        lo, hi = uv[ok].min(axis=0), uv[ok].max(axis=0)
        out.append((lo[0] - margin_px, lo[1] - margin_px, hi[0] + margin_px,
                    hi[1] + margin_px))
    return out

