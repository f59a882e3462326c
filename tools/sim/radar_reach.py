"""The radar service's settings a fusion configuration needs: the defaults (the paper's
prefilter, forward and 25 m), with the prefilter's range out to the farthest a rule
decides (`DecisionSettings.range_bounds_m`: the kinematic rule's `range_max_m`, 80 m
shipped; the paper's 25 m): tracks the radar drops are
tracks the rule never sees. For the simulated stacks (tools/sim/stack.py, the grid's
lockstep loop); deploy/radar.toml sets the same range for deploy/fusion.toml."""

import msgspec

from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.radar import RadarSettings


def radar_for(*configs: FusionConfig | None) -> RadarSettings:
    """The radar service's settings for these fusion instances: the defaults, with the
    prefilter's range out to the farthest any of their rules decides."""
    radar = RadarSettings()
    reach = max((c.fusion.decision.range_bounds_m[1] for c in configs if c is not None),
                default=0.0)
    if reach <= radar.prefilter.max_range_m:
        return radar
    return msgspec.structs.replace(
        radar, prefilter=msgspec.structs.replace(radar.prefilter, max_range_m=reach))
