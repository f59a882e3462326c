"""What a Continental ARS408-21 would report about the simulated world, pure.

A SIMULATION of the sensor's output (the real path is the radar on CAN). Per radar cycle
it returns the objects (object mode) or clusters (cluster mode) in the radar frame: x
forward, y left, origin at the radar on the ego's front (the vehicle frame of
tools/sim/world.py: on a bend it turns with the ego); velocities relative to the radar,
its rotation included (a stationary point ahead drifts sideways at -yaw rate x range).
The dynamic property (stationary, moving, oncoming, crossing) is the radar's own
judgement from the ego speed and yaw rate its host sent it (0x300 / 0x301,
`ReceivedMotion`): without them it takes the ego to stand still, as the ARS408 does.
Imperfections, from `RadarLook`: measurement noise, occasional ghost returns, clutter
(rain), dropouts, several returns per large object (split objects, several clusters),
occlusion by nearer objects, object IDs that are stable but sometimes swap.

Persistent false targets are returns like any other: the ARS408 measures no elevation,
so a metal plate on the road, an overhead sign and a guard rail segment ahead are
reported as stationary objects at their nearest point, every cycle, and its tracker (and
ours) confirms them; so is a persistent multipath ghost (a `ghost` object: the path of a
reflection off a bridge, a truck or a rail, reported where nothing is). They hide nothing
behind them: the radar sees past a plate, under a sign and beside a rail.
"""

import math
from dataclasses import dataclass, replace

import numpy as np

from aeb_radar_camera.tools.messages import ObjectKind
from aeb_radar_camera.tools.sim.scenario import RadarLook
from aeb_radar_camera.tools.sim.world import Body, nearest_point

# Field of view of the ARS408-21: near scan 0.2..70 m within +-60 deg (narrowing with
# range), far scan to 250 m within +-9 deg.
NEAR_RANGE_M = 70.0
NEAR_HALF_FOV_DEG = 60.0
FAR_RANGE_M = 250.0
FAR_HALF_FOV_DEG = 9.0
MIN_RANGE_M = 0.2

# Typical radar cross sections (dBsm) seen from behind or the side. The false targets
# are strong reflectors: a metal plate or manhole cover at a grazing angle, a sign
# gantry's steel, a guard rail's W-beam and posts.
RCS_DBSM = {ObjectKind.CAR: 10.0, ObjectKind.BOX: -8.0, ObjectKind.PEDESTRIAN: -5.0,
            ObjectKind.BICYCLE: -2.0, ObjectKind.PLATE: 2.0, ObjectKind.SIGN: 12.0,
            ObjectKind.GUARD_RAIL: 5.0, ObjectKind.GHOST: -2.0}
# 0x60D Class codes (0 point, 1 car, 3 pedestrian, 5 bicycle, 6 wide)
OBJ_CLASS = {ObjectKind.CAR: 1, ObjectKind.BOX: 0, ObjectKind.PEDESTRIAN: 3,
             ObjectKind.BICYCLE: 5, ObjectKind.PLATE: 0, ObjectKind.SIGN: 6,
             ObjectKind.GUARD_RAIL: 6, ObjectKind.GHOST: 0}
CLUSTERS_PER_OBJECT = {ObjectKind.CAR: (3, 5), ObjectKind.BOX: (1, 1),
                       ObjectKind.PEDESTRIAN: (1, 2), ObjectKind.BICYCLE: (1, 2),
                       ObjectKind.PLATE: (1, 1), ObjectKind.SIGN: (1, 3),
                       ObjectKind.GUARD_RAIL: (1, 2), ObjectKind.GHOST: (1, 1)}
OCCLUDED_FRACTION = 0.7     # an object mostly hidden behind nearer ones is not seen
LARGE_OBJECT_M = 1.5        # objects wider or longer than this may split


class DynProp:
    MOVING = 0
    STATIONARY = 1
    ONCOMING = 2
    CROSSING_MOVING = 6


@dataclass(frozen=True)
class RadarReturn:
    """One object or cluster of a cycle, in the radar frame."""

    id: int
    x_m: float
    y_m: float
    vx_mps: float               # relative to the ego
    vy_mps: float
    rcs_dbsm: float
    dyn_prop: int
    obj_class: int
    length_m: float
    width_m: float
    orientation_deg: float
    prob_of_exist: int          # 0x60C code, 7: <= 100 %
    meas_state: int             # 0x60C code: 1 new, 2 measured
    source: int                 # the scene object's index, -1 for a ghost


@dataclass(frozen=True)
class ReceivedMotion:
    """The ego motion the radar has from its host (0x300 speed, 0x301 yaw rate); None
    where it has none (or only a stale one)."""

    speed_mps: float | None = None
    yaw_rate_dps: float | None = None

    @property
    def rx_state(self) -> int:
        """0x201 MotionRxState: 0 ok, 1 speed missing, 2 yaw missing, 3 both missing."""
        return (1 if self.speed_mps is None else 0) + (2 if self.yaw_rate_dps is None else 0)


def dyn_prop(vx_abs: float, vy_abs: float) -> int:
    if abs(vx_abs) < 0.3 and abs(vy_abs) < 0.3:
        return DynProp.STATIONARY
    if vx_abs < -0.3:
        return DynProp.ONCOMING
    if abs(vy_abs) > abs(vx_abs):
        return DynProp.CROSSING_MOVING
    return DynProp.MOVING


def in_field_of_view(x: float, y: float) -> bool:
    r = math.hypot(x, y)
    if x <= 0 or r < MIN_RANGE_M:
        return False
    az = abs(math.degrees(math.atan2(y, x)))
    return (r <= NEAR_RANGE_M and az <= NEAR_HALF_FOV_DEG) or (
        r <= FAR_RANGE_M and az <= FAR_HALF_FOV_DEG)


@dataclass(frozen=True)
class _Seen:
    body: Body
    corners: np.ndarray     # radar frame
    near: tuple[float, float]
    range_m: float
    az_lo: float
    az_hi: float


def _visible(bodies: list[Body], ego_x: float) -> list[_Seen]:
    """Bodies in the field of view and not hidden behind nearer ones, nearest first."""
    seen: list[_Seen] = []
    for b in bodies:
        c = b.corners() - np.array([ego_x, 0.0])
        if c[:, 0].max() <= 0:
            continue
        nx, ny = nearest_point(c, 0.0, 0.0)
        if not in_field_of_view(nx, ny):
            continue
        az = np.arctan2(c[:, 1], np.maximum(c[:, 0], 1e-3))
        seen.append(_Seen(b, c, (nx, ny), math.hypot(nx, ny), float(az.min()),
                          float(az.max())))
    seen.sort(key=lambda s: s.range_m)
    out: list[_Seen] = []
    for s in seen:
        width = max(s.az_hi - s.az_lo, 1e-6)
        covered = 0.0
        # Union of the nearer visible objects' angular intervals over this one.
        spans = sorted((max(o.az_lo, s.az_lo), min(o.az_hi, s.az_hi)) for o in out
                       if o.range_m < s.range_m and o.az_hi > s.az_lo and o.az_lo < s.az_hi
                       and o.body.kind.is_obstacle)
        end = s.az_lo
        for lo, hi in spans:
            lo = max(lo, end)
            if hi > lo:
                covered += hi - lo
                end = hi
        if covered / width < OCCLUDED_FRACTION:
            out.append(s)
    return out


def radar_sees(bodies: list[Body], index: int) -> bool:
    """Whether the radar can see `bodies[index]` (bodies in the vehicle frame): in its
    field of view and not hidden behind nearer obstacles, by the test its returns use.
    Raises IndexError for an index out of range."""
    target = bodies[index]
    return any(s.body is target for s in _visible(bodies, 0.0))


def _face_points(seen: _Seen, n: int, rng: np.random.Generator) -> list[tuple[float, float]]:
    """n points spread over the edges of a footprint that face the radar."""
    c = seen.corners
    edges = []
    for i in range(4):
        a, b = c[i], c[(i + 1) % 4]
        mid = (a + b) / 2
        normal = np.array([b[1] - a[1], a[0] - b[0]])   # outward for counter-clockwise
        if np.dot(normal, -mid) > 0:
            edges.append((a, b, float(np.hypot(*(b - a)))))
    if not edges:
        return [seen.near] * n
    total = sum(length for _, _, length in edges)
    points = []
    for k in range(n):
        s = (k + rng.uniform(0.2, 0.8)) / n * total
        for i, (a, b, length) in enumerate(edges):
            if s <= length or i == len(edges) - 1:
                p = a + min(s / max(length, 1e-9), 1.0) * (b - a)
                points.append((float(p[0]), float(p[1])))
                break
            s -= length
    return points


class RadarModel:
    """Stateful across cycles only for what the real radar keeps: object IDs, ghosts
    that live a cycle or two, and the random generator (seeded: runs repeat)."""

    def __init__(self, look: RadarLook, seed: int = 0) -> None:
        self.look = look
        self.rng = np.random.default_rng(seed)
        self._ids: dict[tuple[int, int], int] = {}
        self._next_id = 0
        self._ghosts: list[tuple[int, RadarReturn]] = []   # (cycles left, return)

    def _new_id(self) -> int:
        used = set(self._ids.values()) | {g.id for _, g in self._ghosts}
        for _ in range(256):
            candidate = self._next_id
            self._next_id = (self._next_id + 1) % 256
            if candidate not in used:
                return candidate
        raise RuntimeError("more than 256 radar objects")

    def _object_id(self, key: tuple[int, int]) -> tuple[int, bool]:
        if key in self._ids:
            return self._ids[key], False
        self._ids[key] = self._new_id()
        return self._ids[key], True

    def _noisy(self, x: float, y: float, vx: float, vy: float, rcs: float
               ) -> tuple[float, float, float, float, float]:
        look, rng = self.look, self.rng
        return (x + rng.normal(0, look.range_sigma_m), y + rng.normal(0, look.lateral_sigma_m),
                vx + rng.normal(0, look.velocity_sigma_mps),
                vy + rng.normal(0, look.velocity_sigma_mps),
                rcs + rng.normal(0, look.rcs_sigma_dbsm))

    def cycle(self, bodies: list[Body], ego_x_m: float, ego_speed_mps: float,
              yaw_rate_dps: float = 0.0, received: ReceivedMotion | None = None
              ) -> list[RadarReturn]:
        """The returns of one radar cycle for the world as it is now.

        `bodies` in a frame along the ego's heading with the radar at (`ego_x_m`, 0):
        the vehicle frame (`World.vehicle_bodies()`, `ego_x_m` 0), or on a straight road
        the world frame with the ego's x. Velocities over ground; the ego moves at
        `ego_speed_mps` and turns at `yaw_rate_dps`. `received`: the motion the radar's
        host sent it, for the dynamic property; None: the true motion.
        """
        visible = _visible(bodies, ego_x_m)
        motion = _EgoMotion(ego_speed_mps, math.radians(yaw_rate_dps), received)
        if self.look.mode == "objects":
            returns = self._objects(visible, motion)
        else:
            returns = self._clusters(visible, motion)
        returns += self._ghost_returns(ego_speed_mps)
        returns += self._clutter_returns(ego_speed_mps)
        returns.sort(key=lambda r: math.hypot(r.x_m, r.y_m))   # sort index 1: by range
        if self.look.mode == "clusters":
            returns = [_with_id(r, i) for i, r in enumerate(returns)]
        return returns

    def _objects(self, visible: list[_Seen], motion: "_EgoMotion") -> list[RadarReturn]:
        look, rng = self.look, self.rng
        out = []
        alive_keys: set[tuple[int, int]] = set()
        for s in visible:
            b = s.body
            alive_keys.add((b.index, 0))
            if rng.random() < look.dropout_probability:
                continue
            points = [s.near]
            large = max(b.length_m, b.width_m) > LARGE_OBJECT_M
            if large and rng.random() < look.split_probability:
                points += _face_points(s, 1, rng)
                alive_keys.add((b.index, 1))
            for part, (px, py) in enumerate(points):
                oid, new = self._object_id((b.index, part))
                rvx, rvy = motion.relative(b, px, py)
                x, y, vx, vy, rcs = self._noisy(px, py, rvx, rvy, RCS_DBSM[b.kind] - 3.0 * part)
                out.append(RadarReturn(
                    oid, x, y, vx, vy, rcs, motion.dyn_prop(b, px, py), OBJ_CLASS[b.kind],
                    b.length_m, b.width_m, b.yaw_deg, 7, 1 if new else 2, b.index))
        for key in [k for k in self._ids if k not in alive_keys and k[1] == 0]:
            del self._ids[key]
        for key in [k for k in self._ids if k[1] == 1 and k not in alive_keys]:
            del self._ids[key]
        if len(self._ids) >= 2 and rng.random() < look.id_swap_probability:
            a, b2 = rng.choice(len(self._ids), 2, replace=False)
            keys = list(self._ids)
            ka, kb = keys[int(a)], keys[int(b2)]
            self._ids[ka], self._ids[kb] = self._ids[kb], self._ids[ka]
        return out

    def _clusters(self, visible: list[_Seen], motion: "_EgoMotion") -> list[RadarReturn]:
        rng = self.rng
        out = []
        for s in visible:
            b = s.body
            if rng.random() < self.look.dropout_probability:
                continue
            lo, hi = CLUSTERS_PER_OBJECT[b.kind]
            n = int(rng.integers(lo, hi + 1))
            points = [s.near] + (_face_points(s, n - 1, rng) if n > 1 else [])
            rcs0 = RCS_DBSM[b.kind] - 10 * math.log10(n)
            for px, py in points:
                rvx, rvy = motion.relative(b, px, py)
                x, y, vx, vy, rcs = self._noisy(px, py, rvx, rvy, rcs0)
                out.append(RadarReturn(0, x, y, vx, vy, rcs, motion.dyn_prop(b, px, py), 0,
                                       0.0, 0.0, 0.0, 7, 2, b.index))
        return out

    def _ghost_returns(self, ego_speed: float) -> list[RadarReturn]:
        """Clutter that looks like a stationary target for one cycle (two in object
        mode, where the radar's own tracker holds it briefly)."""
        rng = self.rng
        self._ghosts = [(left - 1, g) for left, g in self._ghosts if left > 1]
        for _ in range(int(rng.poisson(self.look.ghost_rate_per_cycle))):
            r = rng.uniform(2.0, 60.0)
            az = math.radians(rng.uniform(-45.0, 45.0))
            ghost = RadarReturn(
                self._new_id() if self.look.mode == "objects" else 0,
                r * math.cos(az), r * math.sin(az),
                -ego_speed + rng.normal(0, 0.5), rng.normal(0, 0.5), rng.uniform(-15.0, 3.0),
                DynProp.STATIONARY, 0, 0.5, 0.5, 0.0, int(rng.integers(1, 4)), 1, -1)
            self._ghosts.append((2 if self.look.mode == "objects" else 1, ghost))
        return [g for _, g in self._ghosts]


    def _clutter_returns(self, ego_speed: float) -> list[RadarReturn]:
        """Rain and spray: weak returns near the radar, one cycle each, closing at about
        the ego's speed (drops and spray hang in the air)."""
        rng = self.rng
        out = []
        for _ in range(int(rng.poisson(self.look.clutter_per_cycle))):
            r = 1.0 + rng.exponential(6.0)
            az = math.radians(rng.uniform(-50.0, 50.0))
            out.append(RadarReturn(
                self._new_id() if self.look.mode == "objects" else 0,
                r * math.cos(az), r * math.sin(az), -ego_speed + rng.normal(0, 1.0),
                rng.normal(0, 1.0), rng.uniform(-30.0, -12.0), DynProp.STATIONARY, 0, 0.2,
                0.2, 0.0, int(rng.integers(0, 3)), 1, -1))
        return out


@dataclass(frozen=True)
class _EgoMotion:
    """The ego's true motion (relative velocities) and the radar's view of it (the
    dynamic property)."""

    speed_mps: float
    yaw_rate_rps: float
    received: ReceivedMotion | None

    def relative(self, b: Body, x: float, y: float) -> tuple[float, float]:
        """The velocity of the point (x, y) of `b` as the turning radar sees it."""
        return (b.vx_mps - self.speed_mps + self.yaw_rate_rps * y,
                b.vy_mps - self.yaw_rate_rps * x)

    def dyn_prop(self, b: Body, x: float, y: float) -> int:
        if self.received is None:
            return dyn_prop(b.vx_mps, b.vy_mps)
        speed = self.received.speed_mps or 0.0
        yaw = math.radians(self.received.yaw_rate_dps or 0.0)
        rvx, rvy = self.relative(b, x, y)
        return dyn_prop(rvx + speed - yaw * y, rvy + yaw * x)


def _with_id(r: RadarReturn, new_id: int) -> RadarReturn:
    return replace(r, id=new_id)
