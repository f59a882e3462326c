"""The simulated world, pure: ego and object kinematics, footprints, collisions and the
ground truth (gap, TTC) the verdict uses. No clocks: `step(dt, brake position)`.

Frames: world (x along the road, y left, origin below the ego's radar at t = 0) and the
radar frame (x forward, y left, origin at the radar on the ego's front; the ego never
steers, so radar = world shifted by the ego's x).
"""

import math
from dataclasses import dataclass, field

import msgspec
import numpy as np

from tools.messages import ObjectKind, SimObject
from tools.sim.scenario import Scenario, SceneObject


class Body(SimObject, frozen=True):
    """An object at one instant, in the world frame: the published SimObject (its
    fields), with its geometry."""

    @classmethod
    def of(cls, obj: SimObject) -> "Body":
        return cls(*msgspec.structs.astuple(obj))

    def corners(self) -> np.ndarray:
        """(4, 2) footprint corners, counter-clockwise."""
        return footprint(self.x_m, self.y_m, self.yaw_deg, self.length_m, self.width_m)

    def shifted(self, dt_s: float) -> "Body":
        """Where this body is after `dt_s` at its current velocity (for extrapolation)."""
        return msgspec.structs.replace(self, x_m=self.x_m + self.vx_mps * dt_s,
                                       y_m=self.y_m + self.vy_mps * dt_s)


def footprint(x: float, y: float, yaw_deg: float, length: float, width: float) -> np.ndarray:
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    half = np.array([[length / 2, width / 2], [-length / 2, width / 2],
                     [-length / 2, -width / 2], [length / 2, -width / 2]])
    rot = np.array([[c, -s], [s, c]])
    return half @ rot.T + np.array([x, y])


def rectangles_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Separating-axis test for two convex quadrilaterals given as (4, 2) corners."""
    for poly in (a, b):
        for i in range(4):
            edge = poly[(i + 1) % 4] - poly[i]
            axis = np.array([-edge[1], edge[0]])
            pa, pb = a @ axis, b @ axis
            if pa.max() < pb.min() or pb.max() < pa.min():
                return False
    return True


def nearest_point(corners: np.ndarray, x: float, y: float) -> tuple[float, float]:
    """The point of a (convex, 4-corner) footprint nearest to (x, y)."""
    p = np.array([x, y])
    best, best_d = corners[0], math.inf
    for i in range(4):
        a, b = corners[i], corners[(i + 1) % 4]
        ab = b - a
        t = float(np.clip(np.dot(p - a, ab) / max(float(np.dot(ab, ab)), 1e-12), 0.0, 1.0))
        q = a + t * ab
        d = float(np.hypot(*(q - p)))
        if d < best_d:
            best, best_d = q, d
    return float(best[0]), float(best[1])


@dataclass
class _Mover:
    spec: SceneObject
    x_m: float
    y_m: float
    started: bool = False
    travelled_m: float = 0.0
    moving: bool = False


@dataclass(frozen=True)
class Collision:
    t_s: float
    object_index: int
    kind: ObjectKind
    ego_speed_mps: float
    relative_speed_mps: float   # closing speed along the road at impact


@dataclass(frozen=True)
class Threat:
    """The object the ego would hit first at current velocities."""

    object_index: int
    gap_m: float                # radar (ego front) to the object's nearest x, along x
    closing_mps: float          # ego speed minus the object's speed along x
    ttc_s: float                # time until the footprints would touch


def _interval(lo: float, hi: float, rate: float) -> tuple[float, float] | None:
    """The times t (any sign) with lo <= rate * t <= hi; None when never."""
    if abs(rate) < 1e-9:
        return (-math.inf, math.inf) if lo <= 0.0 <= hi else None
    a, b = lo / rate, hi / rate
    return (min(a, b), max(a, b))


@dataclass
class EgoState:
    x_m: float = 0.0
    speed_mps: float = 0.0
    decel_mps2: float = 0.0     # current (lagged) deceleration
    odometer_m: float = 0.0


@dataclass
class World:
    """A scenario in motion. Call `step` with the actuator's brake position."""

    scenario: Scenario
    t_s: float = 0.0
    ego: EgoState = field(default_factory=EgoState)
    collision: Collision | None = None
    _movers: list[_Mover] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.ego = EgoState(speed_mps=self.scenario.ego.speed_kph / 3.6)
        self._movers = [_Mover(o, o.x_m, o.y_m) for o in self.scenario.object]
        self._update_triggers()

    # -- kinematics ---------------------------------------------------------------------

    def step(self, dt_s: float, brake_position_pct: float) -> None:
        """Advance by `dt_s`. The deceleration follows `brake_position_pct` (0..100)
        through the ego's brake lag. Raises ValueError for a negative step."""
        if dt_s < 0:
            raise ValueError(f"negative time step {dt_s}")
        if self.collision is not None or dt_s == 0:
            return
        spec = self.scenario.ego
        target = spec.max_decel_mps2 * min(max(brake_position_pct, 0.0), 100.0) / 100.0
        ego = self.ego
        if spec.brake_lag_s > 0:
            ego.decel_mps2 += (target - ego.decel_mps2) * (1 - math.exp(-dt_s / spec.brake_lag_s))
        else:
            ego.decel_mps2 = target
        v0 = ego.speed_mps
        v1 = max(0.0, v0 - ego.decel_mps2 * dt_s)
        moved = (v0 + v1) / 2 * dt_s
        ego.speed_mps = v1
        ego.x_m += moved
        ego.odometer_m += moved
        for m in self._movers:
            motion = m.spec.motion
            m.moving = False
            if motion is None or not m.started or motion.speed_mps == 0:
                continue
            step = motion.speed_mps * dt_s
            if motion.distance_m is not None:
                step = min(step, motion.distance_m - m.travelled_m)
            if step <= 0:
                continue
            h = math.radians(motion.heading_deg)
            m.x_m += step * math.cos(h)
            m.y_m += step * math.sin(h)
            m.travelled_m += step
            m.moving = True
        self.t_s += dt_s
        self._update_triggers()
        self._check_collision()

    def _update_triggers(self) -> None:
        for m in self._movers:
            motion = m.spec.motion
            if motion is None or m.started:
                continue
            if motion.trigger_gap_m is None or self.ego.x_m >= m.x_m - motion.trigger_gap_m:
                m.started = True
                m.moving = motion.speed_mps > 0

    # -- what is where ------------------------------------------------------------------

    def bodies(self) -> list[Body]:
        out = []
        for i, m in enumerate(self._movers):
            length, width, height = m.spec.size()
            vx = vy = 0.0
            motion = m.spec.motion
            if motion is not None and m.moving:
                h = math.radians(motion.heading_deg)
                vx, vy = motion.speed_mps * math.cos(h), motion.speed_mps * math.sin(h)
            out.append(Body(i, m.spec.kind, m.x_m, m.y_m, m.spec.yaw_deg, length, width,
                            height, vx, vy, m.spec.elevation()))
        return out

    def obstacles(self) -> list[Body]:
        """The bodies the ego can hit: false targets (plates, signs, rails) are not."""
        return [b for b in self.bodies() if b.kind.is_obstacle]

    def ego_corners(self) -> np.ndarray:
        spec = self.scenario.ego
        return footprint(self.ego.x_m - spec.length_m / 2, 0.0, 0.0, spec.length_m,
                         spec.width_m)

    def _check_collision(self) -> None:
        ego = self.ego_corners()
        for body in self.obstacles():
            if rectangles_overlap(ego, body.corners()):
                self.collision = Collision(
                    self.t_s, body.index, body.kind, self.ego.speed_mps,
                    self.ego.speed_mps - body.vx_mps)
                return

    def threat(self) -> Threat | None:
        """The object the ego would hit first if everything kept its current velocity
        (the ego its speed, objects theirs): crossing objects count before they reach
        the path. `gap_m` is the longitudinal gap to it; None when nothing would be hit."""
        spec = self.scenario.ego
        half = spec.width_m / 2
        ego_x, v = self.ego.x_m, self.ego.speed_mps
        best: Threat | None = None
        for body in self.obstacles():
            c = body.corners()
            x0, x1 = float(c[:, 0].min()), float(c[:, 0].max())
            y0, y1 = float(c[:, 1].min()), float(c[:, 1].max())
            # Overlap along x: x0 <= ego front and ego rear <= x1, with the relative motion.
            tx = _interval(x0 - ego_x, x1 - ego_x + spec.length_m, v - body.vx_mps)
            ty = _interval(-half - y1, half - y0, body.vy_mps)
            if tx is None or ty is None:
                continue
            start = max(tx[0], ty[0], 0.0)
            if start > min(tx[1], ty[1]):
                continue
            if best is None or start < (best.ttc_s or 0.0):
                closing = v - body.vx_mps
                best = Threat(body.index, x0 - ego_x, closing, start)
        return best

    def in_path_gap(self) -> float | None:
        """Gap to the nearest obstacle ahead that overlaps the ego's width now."""
        return self._gap_in_width(self.obstacles())

    def false_target_gap(self) -> float | None:
        """Gap to the nearest false target (plate, sign, rail, ghost) ahead that overlaps
        the ego's width now: what the radar sees in the path with nothing to hit."""
        return self._gap_in_width([b for b in self.bodies() if not b.kind.is_obstacle])

    def _gap_in_width(self, bodies: list[Body]) -> float | None:
        half = self.scenario.ego.width_m / 2
        gaps = []
        for body in bodies:
            c = body.corners()
            if c[:, 1].max() < -half or c[:, 1].min() > half:
                continue
            gap = float(c[:, 0].min()) - self.ego.x_m
            if gap > -body.length_m:
                gaps.append(gap)
        return min(gaps) if gaps else None

    def passed_everything(self, margin_m: float = 5.0) -> bool:
        """The ego's rear is beyond every object (a no-threat run is over)."""
        rear = self.ego.x_m - self.scenario.ego.length_m
        return all(float(b.corners()[:, 0].max()) + margin_m < rear for b in self.bodies())
