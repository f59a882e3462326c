"""Continental ARS408-21 CAN messages: the signal table, decoder and encoder.

Import from here::

    from aeb_radar_camera.services.radar.ars408 import ObjectGeneral, encode, decode_frame,
    object_cycle_frames
"""

from aeb_radar_camera.services.radar.ars408.codec import (
    Columns,
    EncodeError,
    RadarFrame,
    RadarFrameError,
    decode,
    decode_columns,
    decode_frame,
    encode,
)
from aeb_radar_camera.services.radar.ars408.records import (
    ClusterGeneral,
    ClusterListStatus,
    ClusterQuality,
    ObjectExtended,
    ObjectGeneral,
    ObjectListStatus,
    ObjectQuality,
    RadarConfigFrame,
    RadarStateFrame,
    SpeedInformation,
    Version,
    YawRateInformation,
)
from aeb_radar_camera.services.radar.ars408.table import (
    BY_KIND,
    MESSAGES,
    RMS_CODE_VALUES,
    Kind,
    MessageSpec,
    Signal,
    arbitration_id,
    classify,
)
from aeb_radar_camera.services.radar.ars408.transmissions import (
    cluster_cycle_frames,
    ego_motion_frames,
    object_cycle_frames,
)

__all__ = [
    "BY_KIND",
    "MESSAGES",
    "RMS_CODE_VALUES",
    "ClusterGeneral",
    "ClusterListStatus",
    "ClusterQuality",
    "Columns",
    "EncodeError",
    "Kind",
    "MessageSpec",
    "ObjectExtended",
    "ObjectGeneral",
    "ObjectListStatus",
    "ObjectQuality",
    "RadarConfigFrame",
    "RadarFrame",
    "RadarFrameError",
    "RadarStateFrame",
    "Signal",
    "SpeedInformation",
    "Version",
    "YawRateInformation",
    "arbitration_id",
    "classify",
    "cluster_cycle_frames",
    "decode",
    "decode_columns",
    "decode_frame",
    "ego_motion_frames",
    "encode",
    "object_cycle_frames",
]
