"""Ground truth published by the closed-loop scenario simulator (tools/sim/).

A SIMULATION: nothing on a vehicle publishes it, so it is not among the product's messages
(common/messages/); its key, `SIM_WORLD`, is in the tools' key table (tools/keys.py). The
simulator's camera source (the camera service's synthetic-source plugin,
tools/sim/camera_source.py) renders frames from it; `aeb monitor` and `aeb demo` show it
beside what the stack perceived.
"""

import enum

import msgspec

from common.messages.header import Header


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


class SimObject(msgspec.Struct, frozen=True):
    """One scenario object in the world frame (x along the road, y left, origin on the
    ground below the ego's radar at the start of the run); the simulator's own objects
    are these (tools/sim/world.py's Body adds their geometry)."""

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
    acceleration. `run` increases with every scenario run; `active` is false between runs
    (the ego stands still on an empty road).
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

