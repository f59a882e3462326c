"""The simulated world, pure: ego and object kinematics along the road, footprints,
collisions and the ground truth (gap, TTC) the verdict uses. No clocks: `step(dt, brake
position)`.

Frames (tools/sim/road.py): the world frame (x along the road's first straight, y left,
origin below the ego's radar at t = 0), road coordinates (station along the ego lane's
centre line, lateral offset) in which objects are placed and move, and the vehicle frame
(x forward along the ego's heading, y left, origin at the radar on the ego's front) in
which the radar and the camera see the world. The ego follows the lane centre (lane
keeping): its heading is the road's, its yaw rate its speed times the road's curvature.
Gaps, TTC and "in the path" are measured along the road, so an object beside the road
on the outside of a bend is not in the ego's path.
"""

import math
from dataclasses import dataclass, field

import msgspec
import numpy as np

from aeb_radar_camera.tools.messages import ObjectKind, SimObject
from aeb_radar_camera.tools.sim.road import Pose, Road
from aeb_radar_camera.tools.sim.scenario import Scenario, SceneObject


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

    def seen_from(self, pose: Pose, x_offset_m: float = 0.0) -> "Body":
        """This body in the frame of `pose` (position, yaw and velocity), shifted by
        `x_offset_m` along that frame's x: with the ego's pose, the vehicle frame."""
        x, y = pose.point_to_local(self.x_m, self.y_m)
        vx, vy = pose.rotate_to_local(self.vx_mps, self.vy_mps)
        return msgspec.structs.replace(
            self, x_m=x + x_offset_m, y_m=y,
            yaw_deg=self.yaw_deg - math.degrees(pose.heading_rad), vx_mps=vx, vy_mps=vy)


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
    """An object's state in road coordinates."""

    spec: SceneObject
    s_m: float
    d_m: float
    started: bool = False
    travelled_m: float = 0.0
    moving: bool = False
    speed_mps: float = 0.0
    moving_for_s: float = 0.0     # time since its motion started


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
    gap_m: float                # radar (ego front) to the object's nearest station, along the road
    closing_mps: float          # ego speed minus the object's speed along the road
    ttc_s: float                # time until the footprints would touch


def _interval(lo: float, hi: float, rate: float) -> tuple[float, float] | None:
    """The times t (any sign) with lo <= rate * t <= hi; None when never."""
    if abs(rate) < 1e-9:
        return (-math.inf, math.inf) if lo <= 0.0 <= hi else None
    a, b = lo / rate, hi / rate
    return (min(a, b), max(a, b))


@dataclass
class EgoState:
    s_m: float = 0.0            # station of the radar along the lane centre
    d_m: float = 0.0            # lateral offset from it (lane keeping: 0)
    speed_mps: float = 0.0
    decel_mps2: float = 0.0     # current (lagged) deceleration
    odometer_m: float = 0.0

    @property
    def x_m(self) -> float:
        """The station: on a straight road the radar's world x (the world's pose is
        `World.ego_pose()`)."""
        return self.s_m


@dataclass(frozen=True)
class _RoadBox:
    """A body's extent and rates in road coordinates."""

    s0: float
    s1: float
    d0: float
    d1: float
    s_rate: float
    d_rate: float


@dataclass
class World:
    """A scenario in motion. Call `step` with the actuator's brake position."""

    scenario: Scenario
    t_s: float = 0.0
    ego: EgoState = field(default_factory=EgoState)
    collision: Collision | None = None
    _movers: list[_Mover] = field(default_factory=list)
    road: Road = field(init=False)

    def __post_init__(self) -> None:
        self.road = Road(self.scenario.road)
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
        driver = self.scenario.driver
        if driver.brake_at_s is not None and self.t_s >= driver.brake_at_s:
            target = max(target, driver.brake_decel_mps2)
        ego = self.ego
        if spec.brake_lag_s > 0:
            ego.decel_mps2 += (target - ego.decel_mps2) * (1 - math.exp(-dt_s / spec.brake_lag_s))
        else:
            ego.decel_mps2 = target
        v0 = ego.speed_mps
        v1 = max(0.0, v0 - ego.decel_mps2 * dt_s)
        moved = (v0 + v1) / 2 * dt_s
        ego.speed_mps = v1
        ego.s_m += moved
        ego.odometer_m += moved
        if driver.steer_at_s is not None and driver.lane_change_m:
            done = min(max((self.t_s + dt_s - driver.steer_at_s) / driver.lane_change_s,
                           0.0), 1.0)
            ego.d_m = driver.lane_change_m * (1.0 - math.cos(math.pi * done)) / 2.0
        for m in self._movers:
            self._move(m, dt_s)
        self.t_s += dt_s
        self._update_triggers()
        self._check_collision()

    def _move(self, m: _Mover, dt_s: float) -> None:
        motion = m.spec.motion
        m.moving = False
        if motion is None or not m.started:
            return
        v0 = m.speed_mps
        if motion.decel_mps2 is not None and motion.brake_after_s is not None \
                and m.moving_for_s >= motion.brake_after_s:
            v1 = max(0.0, v0 - motion.decel_mps2 * dt_s)
        else:
            v1 = v0
        m.speed_mps = v1
        m.moving_for_s += dt_s
        step = (v0 + v1) / 2 * dt_s
        if motion.distance_m is not None:
            step = min(step, motion.distance_m - m.travelled_m)
        if step <= 0:
            return
        ds, dd = self._road_rates(m, step)
        m.s_m += ds
        m.d_m += dd
        m.travelled_m += step
        m.moving = True

    def _road_rates(self, m: _Mover, speed: float) -> tuple[float, float]:
        """Station and lateral rates of a mover at `speed` in its motion's direction."""
        motion = m.spec.motion
        if motion is None:
            return 0.0, 0.0
        h = math.radians(motion.heading_deg)
        # Along the road at offset d the station advances 1 / (1 - k d) times as fast.
        stretch = max(1.0 - self.road.curvature_at(m.s_m) * m.d_m, 0.1)
        return speed * math.cos(h) / stretch, speed * math.sin(h)

    def _update_triggers(self) -> None:
        for m in self._movers:
            motion = m.spec.motion
            if motion is None or m.started:
                continue
            if motion.trigger_gap_m is None or self.ego.s_m >= m.s_m - motion.trigger_gap_m:
                m.started = True
                m.speed_mps = motion.speed_mps
                m.moving = motion.speed_mps > 0

    # -- the ego ------------------------------------------------------------------------

    def ego_pose(self) -> Pose:
        """Where the ego's radar (the vehicle frame's origin) is, heading along the road."""
        return self.road.pose_at(self.ego.s_m, self.ego.d_m)

    def yaw_rate_dps(self) -> float:
        """The ego's yaw rate (left positive): its speed times the road's curvature."""
        return math.degrees(self.ego.speed_mps * self.road.curvature_at(self.ego.s_m))

    def ego_corners(self) -> np.ndarray:
        """(4, 2) the ego's footprint in the world (its front at the radar)."""
        spec = self.scenario.ego
        local = footprint(-spec.length_m / 2, 0.0, 0.0, spec.length_m, spec.width_m)
        return self.ego_pose().to_world(local)

    # -- what is where ------------------------------------------------------------------

    def bodies(self) -> list[Body]:
        """Every object now, in the world frame."""
        return [self._body(i, m) for i, m in enumerate(self._movers)]

    def _body(self, index: int, m: _Mover) -> Body:
        length, width, height = m.spec.size()
        heading = self.road.heading_at(m.s_m)
        x, y = self.road.point(m.s_m, m.d_m)
        vx = vy = 0.0
        motion = m.spec.motion
        if motion is not None and m.moving:
            h = heading + math.radians(motion.heading_deg)
            vx, vy = m.speed_mps * math.cos(h), m.speed_mps * math.sin(h)
        return Body(index, m.spec.kind, x, y,
                    m.spec.yaw_deg + math.degrees(heading), length, width, height, vx, vy,
                    m.spec.elevation())

    def vehicle_bodies(self) -> list[Body]:
        """Every object now in the vehicle frame (velocities over ground, in its axes):
        what the radar model and the renderer take."""
        pose = self.ego_pose()
        return [b.seen_from(pose) for b in self.bodies()]

    def obstacles(self) -> list[Body]:
        """The bodies the ego can hit: false targets (plates, signs, rails) are not."""
        return [b for b in self.bodies() if b.kind.is_obstacle]

    def _road_box(self, m: _Mover) -> _RoadBox:
        """A mover's extent in road coordinates: its turned footprint about its station
        and offset (the road taken as straight across the body: a few cm off on the
        tightest bend; collisions use the exact footprints)."""
        length, width, _ = m.spec.size()
        a = math.radians(m.spec.yaw_deg)
        c, s = abs(math.cos(a)), abs(math.sin(a))
        stretch = max(1.0 - self.road.curvature_at(m.s_m) * m.d_m, 0.1)
        half_s = (length / 2 * c + width / 2 * s) / stretch
        half_d = length / 2 * s + width / 2 * c
        s_rate, d_rate = self._road_rates(m, m.speed_mps) if m.moving else (0.0, 0.0)
        return _RoadBox(m.s_m - half_s, m.s_m + half_s, m.d_m - half_d, m.d_m + half_d,
                        s_rate, d_rate)

    def _check_collision(self) -> None:
        spec = self.scenario.ego
        ego_mid = self.ego.s_m - spec.length_m / 2
        reach = math.hypot(spec.length_m, spec.width_m) / 2 + 0.5
        ego: np.ndarray | None = None
        for i, m in enumerate(self._movers):
            if not m.spec.kind.is_obstacle:
                continue
            length, width, _ = m.spec.size()
            # Far along the road is far (a station apart shrinks by at most 1 - |d|/R).
            if 0.8 * abs(m.s_m - ego_mid) > reach + math.hypot(length, width) / 2:
                continue
            ego = self.ego_corners() if ego is None else ego
            body = self._body(i, m)
            if rectangles_overlap(ego, body.corners()):
                along = m.speed_mps * math.cos(math.radians(m.spec.motion.heading_deg)) \
                    if m.spec.motion is not None and m.moving else 0.0
                self.collision = Collision(self.t_s, body.index, body.kind, self.ego.speed_mps,
                                           self.ego.speed_mps - along)
                return

    def threat(self) -> Threat | None:
        """The object the ego would hit first if everything kept its current velocity
        along the road (the ego its speed along the lane, objects their station and
        lateral rates): crossing objects count before they reach the path. `gap_m` is
        the gap along the road to it; None when nothing would be hit."""
        spec = self.scenario.ego
        half = spec.width_m / 2
        ego_s, v = self.ego.s_m, self.ego.speed_mps
        best: Threat | None = None
        for index, m in enumerate(self._movers):
            if not m.spec.kind.is_obstacle:
                continue
            box = self._road_box(m)
            # Overlap along the road: s0 <= ego front and ego rear <= s1, with the
            # relative motion; across it, the ego's width.
            ts = _interval(box.s0 - ego_s, box.s1 - ego_s + spec.length_m, v - box.s_rate)
            td = _interval(-half - box.d1 + self.ego.d_m, half - box.d0 + self.ego.d_m,
                           box.d_rate)
            if ts is None or td is None:
                continue
            start = max(ts[0], td[0], 0.0)
            if start > min(ts[1], td[1]):
                continue
            if best is None or start < best.ttc_s:
                best = Threat(index, box.s0 - ego_s, v - box.s_rate, start)
        return best

    def in_path_gap(self) -> float | None:
        """Gap along the road to the nearest obstacle ahead that overlaps the ego's
        width now."""
        return self._gap_in_width(obstacles=True)

    def false_target_gap(self) -> float | None:
        """Gap to the nearest false target (plate, sign, rail, ghost) ahead that overlaps
        the ego's width now: what the radar sees in the path with nothing to hit."""
        return self._gap_in_width(obstacles=False)

    def _gap_in_width(self, obstacles: bool) -> float | None:
        half = self.scenario.ego.width_m / 2
        gaps = []
        for m in self._movers:
            if m.spec.kind.is_obstacle is not obstacles:
                continue
            box = self._road_box(m)
            if box.d1 < self.ego.d_m - half or box.d0 > self.ego.d_m + half:
                continue
            gap = box.s0 - self.ego.s_m
            if gap > -m.spec.size()[0]:
                gaps.append(gap)
        return min(gaps) if gaps else None

    def passed_everything(self, margin_m: float = 5.0) -> bool:
        """The ego's rear is beyond every object along the road (a no-threat run is
        over)."""
        rear = self.ego.s_m - self.scenario.ego.length_m
        return all(self._road_box(m).s1 + margin_m < rear for m in self._movers)
