"""The keys the tools know: the product's registry (common/keys.py) and the simulator's
ground truth, `sim/world` (a SIMULATION key: nothing on a vehicle publishes it, so the
product's registry leaves it out; `common.bus.Bus` takes any `KeySpec`)."""

from typing import Any

from aeb_radar_camera.common.keys import REGISTRY, Congestion, KeySpec, Priority, QoS
from aeb_radar_camera.tools.messages import SimWorld

SIM_WORLD: KeySpec[SimWorld] = KeySpec(
    "sim_world", "sim/world", SimWorld,
    rate_hz=50.0, max_age_s=1.0, qos=QoS(Priority.DATA_HIGH, Congestion.DROP, express=True),
)

# By name: the registry's, then the simulator's.
KEYS: dict[str, KeySpec[Any]] = {**REGISTRY, SIM_WORLD.name: SIM_WORLD}

# Every key that carries a message (what the monitor, echo, hz, schemas and the recorders
# decode), in KEYS' order.
MESSAGE_KEYS: tuple[KeySpec[Any], ...] = tuple(s for s in KEYS.values()
                                               if s.msg_type is not None)
