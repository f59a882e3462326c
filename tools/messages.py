"""Ground truth published by the closed-loop scenario simulator (tools/sim/).

A SIMULATION: nothing on a vehicle publishes it, so it is not among the product's messages
(common/messages/); its key, `SIM_WORLD`, is in the tools' key table (tools/keys.py). The
simulator's camera source (the camera service's synthetic-source plugin,
tools/sim/camera_source.py) renders frames from it; `aeb monitor` and `aeb demo` show it
beside what the stack perceived.
"""

import enum

import msgspec

from aeb_radar_camera.common.messages.header import Header


class ObjectKind(enum.Enum):
    CAR = "car"
    BOX = "box"                # e.g. the paper's cardboard box
    PEDESTRIAN = "pedestrian"
    BICYCLE = "bicycle"        # with its rider
    # Radar false targets: the radar reports them, but nothing stands in the camera's
    # view and nothing is hit (the ego drives over a plate, under a sign, and follows
    # the road past a rail).
    PLATE = "plate"            # a metal plate or manhole cover, flat on the road
    SIGN = "sign"              # an overhead sign on a gantry, `z_m` above the road
    GUARD_RAIL = "guard_rail"  # one straight segment of a roadside guard rail
    GHOST = "ghost"            # a multipath ghost: a persistent return where nothing is

    @property
    def is_obstacle(self) -> bool:
        """Whether the ego can hit it (false targets are driven over, under or past)."""
        return self not in FALSE_TARGETS


FALSE_TARGETS = frozenset({ObjectKind.PLATE, ObjectKind.SIGN, ObjectKind.GUARD_RAIL,
                           ObjectKind.GHOST})


class Lighting(enum.Enum):
    """The light a scenario plays in (what the camera sees; rain also clutters the radar)."""

    DAY = "day"
    DUSK = "dusk"              # a third of the daylight, more sensor noise
    NIGHT = "night"            # ambient light only, the ego's low beams light the rest
    RAIN = "rain"              # overcast daylight: lower contrast, noise, streaks; radar clutter


class RoadGeometry(msgspec.Struct, frozen=True):
    """The ego lane's centre line: straight from the start, then (with `radius_m`) an arc
    of that signed radius (positive: a left bend) from station `curve_start_m` on. (The
    scenario files' `[road]`, validated there: tools/sim/scenario.py.)"""

    curve_start_m: float = 0.0
    radius_m: float | None = None


class SimObject(msgspec.Struct, frozen=True):
    """One scenario object in the world frame (x along the road's first straight, y left,
    origin on the ground below the ego's radar at the start of the run; on a straight road
    x is along the road); the simulator's own objects are these (tools/sim/world.py's
    Body adds their geometry)."""

    index: int
    kind: ObjectKind           # as its value on the wire: "car", "box", ...
    x_m: float                 # centre of the footprint
    y_m: float
    yaw_deg: float
    length_m: float
    width_m: float
    height_m: float
    vx_mps: float
    vy_mps: float
    z_m: float = 0.0           # bottom above the road (an overhead sign)


class SimWorld(msgspec.Struct, frozen=True):
    """The simulated world at `header.stamp_ns` (wall clock).

    Consumers extrapolate to their own capture time with the velocities and the ego's
    acceleration (the ego along the road: tools/sim/camera_source.py). `run` increases
    with every scenario run; `active` is false between runs (the ego stands still on an
    empty road). The ego's pose is that of its radar (the vehicle frame's origin); its
    station `ego_s_m` runs along the lane centre of `road` (None in recordings made before
    roads could bend: then `ego_x_m`).
    """

    header: Header
    scenario: str
    run: int
    active: bool
    t_s: float                 # time since the run started
    ego_x_m: float
    ego_speed_mps: float
    ego_accel_mps2: float      # negative while braking
    gap_m: float | None        # ground truth: nearest in-path object, None when none
    ttc_s: float | None
    objects: tuple[SimObject, ...]
    seed: int                  # the scenario's seed (textures, noise)
    brightness: float          # camera look: 1 day, lower at dusk
    noise: float               # camera sensor noise, grey levels
    ego_y_m: float = 0.0
    ego_heading_deg: float = 0.0    # left positive
    ego_yaw_rate_dps: float = 0.0   # left positive: speed x the road's curvature
    ego_s_m: float | None = None    # station along the lane centre
    ego_d_m: float = 0.0            # lateral offset from the lane centre, left positive
    road: RoadGeometry = msgspec.field(default_factory=RoadGeometry)
    lighting: Lighting = Lighting.DAY

    def ego_station(self) -> float:
        return self.ego_x_m if self.ego_s_m is None else self.ego_s_m

