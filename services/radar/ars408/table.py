"""The ARS408-21 CAN database as a table: the one place where decoding is defined.

Every signal is Motorola (big-endian) and unsigned, placed by its most significant bit
(`msb_byte`, `msb_bit` with bit 7 = MSB of the byte), exactly as in a DBC start bit
(`start = msb_byte * 8 + msb_bit`). The scalar codec, the vectorised cycle decoder, the
encoder and the exported DBC file are all generated from this table.

Source: /work/shared/ARS408.md (checked on the real recording in tests/data/ars408).
Physical value = raw * scale + offset. `valid` is the physical range a real radar can
produce: a frame with a value outside it is rejected (counted by reason).
"""

import enum
from dataclasses import dataclass, field
from typing import Any

from aeb_radar_camera.common.messages.radar import OBJECT_CLASSES
from aeb_radar_camera.services.radar.ars408 import records


class Kind(enum.Enum):
    OBJECT_STATUS = "object_status"
    OBJECT_GENERAL = "object_general"
    OBJECT_QUALITY = "object_quality"
    OBJECT_EXTENDED = "object_extended"
    CLUSTER_STATUS = "cluster_status"
    CLUSTER_GENERAL = "cluster_general"
    CLUSTER_QUALITY = "cluster_quality"
    RADAR_STATE = "radar_state"
    VERSION = "version"
    RADAR_CONFIG = "radar_config"
    SPEED = "speed"
    YAW_RATE = "yaw_rate"


@dataclass(frozen=True)
class Signal:
    attr: str                   # attribute of the record NamedTuple
    dbc_name: str
    msb_byte: int
    msb_bit: int
    length: int
    scale: float = 1.0
    offset: float = 0.0
    unit: str = ""
    valid: tuple[float, float] | None = None
    choices: dict[int, str] = field(default_factory=dict)

    @property
    def shift(self) -> int:
        """Right shift of the 64-bit big-endian frame word that puts the LSB at bit 0."""
        return (7 - self.msb_byte) * 8 + self.msb_bit - self.length + 1

    @property
    def mask(self) -> int:
        return (1 << self.length) - 1

    @property
    def is_integer(self) -> bool:
        return self.scale == 1.0 and self.offset == 0.0

    @property
    def dbc_start_bit(self) -> int:
        return self.msb_byte * 8 + self.msb_bit


@dataclass(frozen=True)
class MessageSpec:
    kind: Kind
    dbc_name: str
    base_id: int
    dlc: int                    # bytes the radar sends; shorter frames are rejected
    sender: str                 # "ARS408" or "HOST"
    record: type[Any]
    signals: tuple[Signal, ...]
    comment: str = ""

    def __post_init__(self) -> None:
        names = tuple(s.attr for s in self.signals)
        if names != self.record._fields:
            raise AssertionError(f"{self.dbc_name}: signals {names} != {self.record._fields}")
        for s in self.signals:
            if s.shift < 0 or (8 - self.dlc) * 8 > s.shift:
                raise AssertionError(f"{self.dbc_name}.{s.dbc_name} lies outside the DLC")


DYN_PROP = {0: "moving", 1: "stationary", 2: "oncoming", 3: "stationary candidate",
            4: "unknown", 5: "crossing stationary", 6: "crossing moving", 7: "stopped"}
OBJ_CLASS = dict(enumerate(OBJECT_CLASSES))
MEAS_STATE = {0: "deleted", 1: "new", 2: "measured", 3: "predicted", 4: "deleted for merge",
              5: "new from merge"}
PROB_OF_EXIST = {0: "invalid", 1: "<25%", 2: "<50%", 3: "<75%", 4: "<90%", 5: "<99%",
                 6: "<99.9%", 7: "<=100%"}
AMBIG_STATE = {0: "invalid", 1: "ambiguous", 2: "staggered ramp", 3: "unambiguous",
               4: "stationary candidate"}
INVALID_STATE = {0: "valid", 1: "invalid: low RCS", 2: "invalid: near field",
                 3: "invalid: far range not confirmed", 4: "valid: low RCS",
                 5: "reserved", 6: "invalid: mirror", 7: "invalid: outside FOV",
                 8: "valid: elevation", 9: "valid: child", 10: "valid: 50 deg artefact",
                 11: "valid: no local maximum", 12: "valid: artefact", 13: "reserved",
                 14: "invalid: harmonics", 15: "valid: near field above 95 m",
                 16: "valid: multi-target", 17: "valid: suspicious angle"}
OUTPUT_TYPE = {0: "none", 1: "objects", 2: "clusters"}
SORT_INDEX = {0: "none", 1: "range", 2: "RCS"}
MOTION_RX = {0: "ok", 1: "speed missing", 2: "yaw rate missing", 3: "speed and yaw missing"}
RCS_THRESHOLD = {0: "standard", 1: "high sensitivity"}
SPEED_DIRECTION = {0: "standstill", 1: "forward", 2: "reverse"}

# 5-bit standard-deviation codes of 0x60C/0x702: code -> upper bound (m or m/s); 31 invalid.
RMS_CODE_VALUES: tuple[float, ...] = (
    0.005, 0.006, 0.008, 0.011, 0.014, 0.018, 0.023, 0.029, 0.038, 0.049, 0.063, 0.081,
    0.105, 0.135, 0.174, 0.224, 0.288, 0.371, 0.478, 0.616, 0.794, 1.023, 1.317, 1.697,
    2.187, 2.817, 3.630, 4.676, 6.025, 7.762, 10.0,
)
RMS_INVALID = 31

_RANGE_M = (-10.0, 300.0)    # ARS408 far range is 250 m; nothing behind the radar
_LATERAL_M = (-100.0, 100.0)


def _flag(fld: str, dbc: str, byte: int, bit: int) -> Signal:
    return Signal(fld, dbc, byte, bit, 1)


def _id(prefix: str) -> Signal:
    return Signal("id", f"{prefix}_ID", 0, 7, 8)


# Bytes 0..3 of 0x60C and 0x702: the ID and four 5-bit standard-deviation codes.
_QUALITY_HEAD = (
    Signal("id", "ID", 0, 7, 8),
    Signal("dist_long_rms", "DistLong_rms", 1, 7, 5, unit="code"),
    Signal("dist_lat_rms", "DistLat_rms", 1, 2, 5, unit="code"),
    Signal("vrel_long_rms", "VrelLong_rms", 2, 5, 5, unit="code"),
    Signal("vrel_lat_rms", "VrelLat_rms", 2, 0, 5, unit="code"),
)

# Bytes 4..7 of 0x60B and 0x701.
_KINEMATICS_TAIL = (
    Signal("vrel_long_mps", "VrelLong", 4, 7, 10, 0.25, -128.0, "m/s"),
    Signal("vrel_lat_mps", "VrelLat", 5, 5, 9, 0.25, -64.0, "m/s"),
    Signal("dyn_prop", "DynProp", 6, 2, 3, choices=DYN_PROP),
    Signal("rcs_dbsm", "RCS", 7, 7, 8, 0.5, -64.0, "dBsm"),
)


def _prefixed(prefix: str, signals: tuple[Signal, ...]) -> tuple[Signal, ...]:
    return tuple(
        Signal(s.attr, f"{prefix}_{s.dbc_name}", s.msb_byte, s.msb_bit, s.length, s.scale,
               s.offset, s.unit, s.valid, s.choices)
        for s in signals
    )


MESSAGES: tuple[MessageSpec, ...] = (
    MessageSpec(Kind.OBJECT_STATUS, "Obj_0_Status", 0x60A, 4, "ARS408",
                records.ObjectListStatus, (
                    Signal("n_objects", "Obj_NofObjects", 0, 7, 8),
                    Signal("meas_counter", "Obj_MeasCounter", 1, 7, 16),
                    Signal("interface_version", "Obj_InterfaceVersion", 3, 7, 4),
                ), "First frame of an object cycle; its count is the authority."),
    MessageSpec(Kind.OBJECT_GENERAL, "Obj_1_General", 0x60B, 8, "ARS408",
                records.ObjectGeneral, (
                    _id("Obj"),
                    Signal("dist_long_m", "Obj_DistLong", 1, 7, 13, 0.2, -500.0, "m",
                           _RANGE_M),
                    Signal("dist_lat_m", "Obj_DistLat", 2, 2, 11, 0.2, -204.6, "m",
                           _LATERAL_M),
                    *_prefixed("Obj", _KINEMATICS_TAIL),
                ), "One per object. DistLat is left positive."),
    MessageSpec(Kind.OBJECT_QUALITY, "Obj_2_Quality", 0x60C, 7, "ARS408",
                records.ObjectQuality, (
                    *_prefixed("Obj", _QUALITY_HEAD),
                    Signal("meas_state", "Obj_MeasState", 6, 4, 3, valid=(0, 5),
                           choices=MEAS_STATE),
                    Signal("prob_of_exist", "Obj_ProbOfExist", 6, 7, 3, choices=PROB_OF_EXIST),
                ), "One per object when quality output is enabled."),
    MessageSpec(Kind.OBJECT_EXTENDED, "Obj_3_Extended", 0x60D, 8, "ARS408",
                records.ObjectExtended, (
                    _id("Obj"),
                    Signal("arel_long_mps2", "Obj_ArelLong", 1, 7, 11, 0.01, -10.0, "m/s2"),
                    Signal("arel_lat_mps2", "Obj_ArelLat", 2, 4, 9, 0.01, -2.5, "m/s2"),
                    Signal("obj_class", "Obj_Class", 3, 2, 3, valid=(0, 6), choices=OBJ_CLASS),
                    Signal("orientation_deg", "Obj_OrientationAngle", 4, 7, 10, 0.4, -180.0,
                           "deg", (-180.0, 180.0)),
                    Signal("length_m", "Obj_Length", 6, 7, 8, 0.2, 0.0, "m"),
                    Signal("width_m", "Obj_Width", 7, 7, 8, 0.2, 0.0, "m"),
                ), "One per object when extended output is enabled."),
    MessageSpec(Kind.CLUSTER_STATUS, "Cluster_0_Status", 0x600, 5, "ARS408",
                records.ClusterListStatus, (
                    Signal("n_near", "Cluster_NofClustersNear", 0, 7, 8),
                    Signal("n_far", "Cluster_NofClustersFar", 1, 7, 8),
                    Signal("meas_counter", "Cluster_MeasCounter", 2, 7, 16),
                    Signal("interface_version", "Cluster_InterfaceVersion", 4, 7, 4),
                ), "First frame of a cluster cycle; near + far is the authority."),
    MessageSpec(Kind.CLUSTER_GENERAL, "Cluster_1_General", 0x701, 8, "ARS408",
                records.ClusterGeneral, (
                    _id("Cluster"),
                    Signal("dist_long_m", "Cluster_DistLong", 1, 7, 13, 0.2, -500.0, "m",
                           _RANGE_M),
                    Signal("dist_lat_m", "Cluster_DistLat", 2, 1, 10, 0.2, -102.3, "m",
                           _LATERAL_M),
                    *_prefixed("Cluster", _KINEMATICS_TAIL),
                ), "One per cluster. DistLat is left positive."),
    MessageSpec(Kind.CLUSTER_QUALITY, "Cluster_2_Quality", 0x702, 5, "ARS408",
                records.ClusterQuality, (
                    *_prefixed("Cluster", _QUALITY_HEAD),
                    Signal("pdh0", "Cluster_Pdh0", 3, 2, 3, choices=PROB_OF_EXIST),
                    Signal("ambig_state", "Cluster_AmbigState", 4, 2, 3, valid=(0, 4),
                           choices=AMBIG_STATE),
                    Signal("invalid_state", "Cluster_InvalidState", 4, 7, 5, valid=(0, 17),
                           choices=INVALID_STATE),
                ), "One per cluster when quality output is enabled."),
    MessageSpec(Kind.RADAR_STATE, "RadarState", 0x201, 8, "ARS408",
                records.RadarStateFrame, (
                    _flag("nvm_read_ok", "RadarState_NVMReadStatus", 0, 6),
                    Signal("max_distance_m", "RadarState_MaxDistanceCfg", 1, 7, 10, 2.0, 0.0,
                           "m"),
                    _flag("persistent_error", "RadarState_Persistent_Error", 2, 5),
                    _flag("interference", "RadarState_Interference", 2, 4),
                    _flag("temperature_error", "RadarState_Temperature_Error", 2, 3),
                    _flag("temporary_error", "RadarState_Temporary_Error", 2, 2),
                    _flag("voltage_error", "RadarState_Voltage_Error", 2, 1),
                    Signal("sensor_id", "RadarState_SensorID", 4, 2, 3),
                    Signal("sort_index", "RadarState_SortIndex", 4, 6, 3, choices=SORT_INDEX),
                    Signal("motion_rx_state", "RadarState_MotionRxState", 5, 7, 2,
                           choices=MOTION_RX),
                    _flag("send_ext_info", "RadarState_SendExtInfoCfg", 5, 5),
                    _flag("send_quality", "RadarState_SendQualityCfg", 5, 4),
                    Signal("output_type", "RadarState_OutputTypeCfg", 5, 3, 2,
                           choices=OUTPUT_TYPE),
                    Signal("rcs_threshold", "RadarState_RCS_Threshold", 7, 4, 3,
                           choices=RCS_THRESHOLD),
                ), "About once a second; confirms a configuration write."),
    MessageSpec(Kind.VERSION, "VersionID", 0x700, 4, "ARS408", records.Version, (
        Signal("major", "Version_MajorRelease", 0, 7, 8),
        Signal("minor", "Version_MinorRelease", 1, 7, 8),
        Signal("patch", "Version_PatchLevel", 2, 7, 8),
    ), "Firmware version."),
    MessageSpec(Kind.RADAR_CONFIG, "RadarCfg", 0x200, 8, "HOST", records.RadarConfigFrame, (
        _flag("max_distance_valid", "RadarCfg_MaxDistance_valid", 0, 0),
        _flag("sensor_id_valid", "RadarCfg_SensorID_valid", 0, 1),
        _flag("radar_power_valid", "RadarCfg_RadarPower_valid", 0, 2),
        _flag("output_type_valid", "RadarCfg_OutputType_valid", 0, 3),
        _flag("send_quality_valid", "RadarCfg_SendQuality_valid", 0, 4),
        _flag("send_ext_info_valid", "RadarCfg_SendExtInfo_valid", 0, 5),
        _flag("sort_index_valid", "RadarCfg_SortIndex_valid", 0, 6),
        _flag("store_in_nvm_valid", "RadarCfg_StoreInNVM_valid", 0, 7),
        Signal("max_distance_m", "RadarCfg_MaxDistance", 1, 7, 10, 2.0, 0.0, "m"),
        Signal("sensor_id", "RadarCfg_SensorID", 4, 2, 3),
        Signal("output_type", "RadarCfg_OutputType", 4, 4, 2, choices=OUTPUT_TYPE),
        Signal("radar_power", "RadarCfg_RadarPower", 4, 7, 3),
        _flag("ctrl_relay_valid", "RadarCfg_CtrlRelay_valid", 5, 0),
        _flag("ctrl_relay", "RadarCfg_CtrlRelay", 5, 1),
        _flag("send_quality", "RadarCfg_SendQuality", 5, 2),
        _flag("send_ext_info", "RadarCfg_SendExtInfo", 5, 3),
        Signal("sort_index", "RadarCfg_SortIndex", 5, 6, 3, choices=SORT_INDEX),
        _flag("store_in_nvm", "RadarCfg_StoreInNVM", 5, 7),
        _flag("rcs_threshold_valid", "RadarCfg_RCS_Threshold_valid", 6, 0),
        Signal("rcs_threshold", "RadarCfg_RCS_Threshold", 6, 3, 3, choices=RCS_THRESHOLD),
    ), "Host to radar. A bad write can stop the output: confirm it from 0x201."),
    MessageSpec(Kind.SPEED, "SpeedInformation", 0x300, 2, "HOST",
                records.SpeedInformation, (
                    Signal("direction", "RadarDevice_SpeedDirection", 0, 7, 2,
                           choices=SPEED_DIRECTION),
                    Signal("speed_mps", "RadarDevice_Speed", 0, 4, 13, 0.02, 0.0, "m/s"),
                ), "Host to radar: ego speed."),
    MessageSpec(Kind.YAW_RATE, "YawRateInformation", 0x301, 2, "HOST",
                records.YawRateInformation, (
                    Signal("yaw_rate_dps", "RadarDevice_YawRate", 0, 7, 16, 0.01, -327.68,
                           "deg/s"),
                ), "Host to radar: ego yaw rate, left positive."),
)

BY_KIND: dict[Kind, MessageSpec] = {m.kind: m for m in MESSAGES}
BY_RECORD: dict[type[Any], MessageSpec] = {m.record: m for m in MESSAGES}

MAX_SENSORS = 8
SENSOR_ID_STRIDE = 0x10


def arbitration_id(kind: Kind, sensor_id: int = 0) -> int:
    """The CAN ID of `kind` for a radar with SensorID `sensor_id` (ID + 0x10 * s).

    Raises ValueError for a sensor ID outside 0..7.
    """
    if not 0 <= sensor_id < MAX_SENSORS:
        raise ValueError(f"sensor_id {sensor_id} outside 0..{MAX_SENSORS - 1}")
    return BY_KIND[kind].base_id + SENSOR_ID_STRIDE * sensor_id


# Every (ID + 0x10 * s) is distinct across messages and sensors, so one dict classifies.
ID_TABLE: dict[int, tuple[MessageSpec, int]] = {
    m.base_id + SENSOR_ID_STRIDE * s: (m, s) for m in MESSAGES for s in range(MAX_SENSORS)
}
assert len(ID_TABLE) == len(MESSAGES) * MAX_SENSORS


def classify(arb_id: int) -> tuple[MessageSpec, int] | None:
    """(message spec, sensor ID) of an ARS408 CAN ID, or None for any other ID."""
    return ID_TABLE.get(arb_id)
