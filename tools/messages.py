"""Ground truth published by the closed-loop scenario simulator (tools/sim/).

A SIMULATION: nothing on a vehicle publishes it, so it is not among the product's messages
(common/messages/); its key, `SIM_WORLD`, is in the tools' key table (tools/keys.py). The
simulator's camera source (the camera service's synthetic-source plugin,
tools/sim/camera_source.py) renders frames from it; `aeb monitor` and `aeb demo` show it
beside what the stack perceived.
"""

import msgspec

from common.messages.header import Header


class SimObject(msgspec.Struct, frozen=True):
    """One scenario object in the world frame (x along the road, y left, origin on the
    ground below the ego's radar at the start of the run)."""

    index: int
    kind: str                  # car | box | pedestrian | bicycle | plate | sign | guard_rail
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

