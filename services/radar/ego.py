"""Ego speed and yaw rate (EgoMotion on `vehicle/motion`) to every radar as 0x300 / 0x301.
Pure: the shell passes the current times and sends the returned frames.

The ARS408 uses them to classify objects as stationary or moving (DynProp); relative
positions and velocities do not depend on them.
"""

from aeb_radar_camera.common.config.radar import EgoMotionSettings
from aeb_radar_camera.common.counters import ReasonCounter
from aeb_radar_camera.common.messages.vehicle import EgoMotion
from aeb_radar_camera.services.radar.ars408.codec import EncodeError, RadarFrame
from aeb_radar_camera.services.radar.ars408.transmissions import ego_motion_frames


class EgoMotionForwarder:
    """Rejections by reason in `rejected`: ``stale`` (older than max_age_s),
    ``out_of_range`` (not representable), ``throttled`` (closer than min_interval_s)."""

    def __init__(self, settings: EgoMotionSettings, sensor_ids: list[int]) -> None:
        self.settings = settings
        self.sensor_ids = sensor_ids
        self.rejected = ReasonCounter()
        self._last_mono_ns: int | None = None
        self._max_age_ns = int(settings.max_age_s * 1e9)
        self._interval_ns = int(settings.min_interval_s * 1e9)

    def on_motion(self, msg: EgoMotion, now_wall_ns: int, now_mono_ns: int) -> list[RadarFrame]:
        if not self.settings.forward:
            return []
        if now_wall_ns - msg.header.stamp_ns > self._max_age_ns:
            self.rejected.add("stale")
            return []
        if self._last_mono_ns is not None and now_mono_ns - self._last_mono_ns < self._interval_ns:
            self.rejected.add("throttled")
            return []
        frames: list[RadarFrame] = []
        try:
            for sid in self.sensor_ids:
                frames += ego_motion_frames(msg.speed_mps, msg.yaw_rate_dps, sid)
        except EncodeError:
            self.rejected.add("out_of_range")
            return []
        self._last_mono_ns = now_mono_ns
        return frames
