"""Writing the radar configuration (0x200) and confirming it from 0x201. Pure.

A bad 0x200 can stop the radar's output, so the service trusts only what the radar
reports back: the write is confirmed when a 0x201 shows every requested field; it is
re-sent after `confirm_timeout_s` up to `attempts` times, then reported as failed with
the fields that differ. A later 0x201 that differs again makes the radar not ready.
"""

import enum

from aeb_radar_camera.common.config.radar import OutputTypeCfg, RadarWriteSettings
from aeb_radar_camera.services.radar.ars408.codec import RadarFrame, encode
from aeb_radar_camera.services.radar.ars408.records import RadarConfigFrame, RadarStateFrame

OUTPUT_TYPE_CODE = {OutputTypeCfg.OBJECTS: 1, OutputTypeCfg.CLUSTERS: 2}
OUTPUT_TYPE_NAME = {0: "none", 1: "objects", 2: "clusters"}


def config_frame_record(s: RadarWriteSettings, sensor_id: int) -> RadarConfigFrame:
    """The 0x200 payload for `s` (SensorID is sent for completeness but never flagged valid)."""
    power = s.radar_power is not None
    return RadarConfigFrame(
        max_distance_valid=1, sensor_id_valid=0, radar_power_valid=int(power),
        output_type_valid=1, send_quality_valid=1, send_ext_info_valid=1, sort_index_valid=1,
        store_in_nvm_valid=1, max_distance_m=s.max_distance_m, sensor_id=sensor_id,
        output_type=OUTPUT_TYPE_CODE[s.output_type], radar_power=s.radar_power or 0,
        send_quality=int(s.send_quality), send_ext_info=int(s.send_ext_info),
        sort_index=s.sort_index, store_in_nvm=int(s.store_in_nvm), rcs_threshold_valid=1,
        rcs_threshold=s.rcs_threshold,
    )


def differences(s: RadarWriteSettings, state: RadarStateFrame) -> list[str]:
    """Requested fields the radar's state does not show, as ``field=have (want X)``."""
    want = {
        "output_type": OUTPUT_TYPE_CODE[s.output_type],
        "max_distance_m": s.max_distance_m,
        "send_quality": int(s.send_quality),
        "send_ext_info": int(s.send_ext_info),
        "sort_index": s.sort_index,
        "rcs_threshold": s.rcs_threshold,
    }
    out = []
    for name, value in want.items():
        have = getattr(state, name)
        if int(have) != value:
            if name == "output_type":
                out.append(f"output_type={OUTPUT_TYPE_NAME.get(int(have), have)} "
                           f"(want {s.output_type.value})")
            else:
                out.append(f"{name}={int(have)} (want {value})")
    return out


class WriteState(enum.Enum):
    DISABLED = "disabled"
    WAITING = "waiting"
    CONFIRMED = "confirmed"
    FAILED = "failed"


class ConfigWriter:
    def __init__(self, settings: RadarWriteSettings, sensor_id: int) -> None:
        self.settings = settings
        self.sensor_id = sensor_id
        self.state = WriteState.DISABLED
        self.attempt = 0
        self.frames_sent = 0
        self._deadline_ns = 0
        self._timeout_ns = int(settings.confirm_timeout_s * 1e9)
        self._last_diff: list[str] = []

    def frame(self) -> RadarFrame:
        return encode(config_frame_record(self.settings, self.sensor_id), self.sensor_id)

    def start(self, mono_ns: int) -> list[RadarFrame]:
        """Frames to send when the bus (re)opens: the first write, if enabled."""
        if not self.settings.enabled:
            return []
        self.state = WriteState.WAITING
        self.attempt = 0
        return self._send(mono_ns)

    def _send(self, mono_ns: int) -> list[RadarFrame]:
        self.attempt += 1
        self.frames_sent += 1
        self._deadline_ns = mono_ns + self._timeout_ns
        return [self.frame()]

    def on_state(self, state: RadarStateFrame) -> None:
        if self.state is WriteState.DISABLED:
            return
        self._last_diff = differences(self.settings, state)
        if not self._last_diff:
            self.state = WriteState.CONFIRMED
        elif self.state is WriteState.CONFIRMED:
            self.state = WriteState.FAILED   # the radar changed after confirming

    def poll(self, mono_ns: int) -> list[RadarFrame]:
        """Frames to re-send when the confirmation is late."""
        if self.state is not WriteState.WAITING or mono_ns < self._deadline_ns:
            return []
        if self.attempt >= self.settings.attempts:
            self.state = WriteState.FAILED
            return []
        return self._send(mono_ns)

    def not_ready_reason(self) -> str:
        """Empty when the configuration is confirmed (or not written)."""
        if self.state is WriteState.WAITING:
            return (f"waiting for 0x201 to confirm the configuration "
                    f"(attempt {self.attempt}/{self.settings.attempts})")
        if self.state is WriteState.FAILED:
            what = ", ".join(self._last_diff) or "no 0x201 received"
            return f"radar state differs from the configuration written: {what}"
        return ""
