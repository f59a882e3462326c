"""The ego-motion forwarder: any speed and yaw rate either becomes 0x300 / 0x301 frames or
is counted as out of range; NaN and infinities never raise."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aeb_radar_camera.common.config.radar import EgoMotionSettings
from aeb_radar_camera.common.messages.header import Header
from aeb_radar_camera.common.messages.vehicle import EgoMotion
from aeb_radar_camera.services.radar.ego import EgoMotionForwarder

NOW_NS = 10**18
FORWARD = EgoMotionSettings(forward=True, min_interval_s=0.0)


def motion(speed: float, yaw: float) -> EgoMotion:
    return EgoMotion(header=Header(seq=0, source="test", stamp_ns=NOW_NS, pub_mono_ns=0),
                     speed_mps=speed, yaw_rate_dps=yaw)


@pytest.mark.parametrize(("speed", "yaw"), [
    (math.nan, 0.0), (0.0, math.nan), (math.inf, 0.0), (-math.inf, 0.0), (0.0, math.inf),
    (0.0, -math.inf), (math.nan, math.inf),
])
def test_a_non_finite_speed_or_yaw_is_counted_out_of_range(speed, yaw):
    fwd = EgoMotionForwarder(FORWARD, [0, 1])
    assert fwd.on_motion(motion(speed, yaw), NOW_NS, 1) == []
    assert fwd.rejected.snapshot() == {"out_of_range": 1}
    # the next good sample still goes out
    assert len(fwd.on_motion(motion(8.3, -4.5), NOW_NS, 2)) == 4


@settings(max_examples=500, deadline=None)
@given(speed=st.floats(), yaw=st.floats())
def test_any_speed_and_yaw_is_frames_or_a_counted_rejection(speed, yaw):
    fwd = EgoMotionForwarder(FORWARD, [0])
    frames = fwd.on_motion(motion(speed, yaw), NOW_NS, 1)
    assert len(frames) == 2 or fwd.rejected.get("out_of_range") == 1
    if not (math.isfinite(speed) and math.isfinite(yaw)):
        assert frames == []
