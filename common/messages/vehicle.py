"""Vehicle state shared on the bus (from the vehicle's CAN gateway, or the simulator)."""

import msgspec

from common.messages.header import Header


class EgoMotion(msgspec.Struct, frozen=True):
    """Ego speed (forward positive, reverse negative) and yaw rate (left positive)."""

    header: Header
    speed_mps: float
    yaw_rate_dps: float
