"""The radar service's settings a fusion configuration needs: the defaults (the paper's
prefilter, forward and 25 m), with the prefilter's range out to the farthest kinematic
range gate (`[fusion.decision.kinematic] range_max_m`): tracks the radar drops are
tracks the rule never sees. For the simulated stacks (tools/sim/stack.py, the grid's
lockstep loop); deploy/radar.toml sets the same range for deploy/fusion.toml."""

import msgspec

from common.config.fusion import FusionConfig, RuleName
from common.config.radar import RadarSettings


def radar_for(*configs: FusionConfig | None) -> RadarSettings:
    """The radar service's settings for these fusion instances: the defaults, with the
    prefilter's range out to the farthest kinematic range gate among them."""
    radar = RadarSettings()
    reach = max((c.fusion.decision.kinematic.range_max_m for c in configs
                 if c is not None and c.fusion.decision.rule is RuleName.KINEMATIC),
                default=0.0)
    if reach <= radar.prefilter.max_range_m:
        return radar
    return msgspec.structs.replace(
        radar, prefilter=msgspec.structs.replace(radar.prefilter, max_range_m=reach))
