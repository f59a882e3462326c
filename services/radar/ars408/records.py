"""Decoded ARS408 messages in physical units (one NamedTuple per CAN message).

Field order equals the signal order of the message in `table.py`; a test checks it.
The `id` field of list messages is the radar's object/cluster ID (0..255).
"""

from typing import NamedTuple


class ObjectListStatus(NamedTuple):
    """0x60A: first frame of an object cycle."""

    n_objects: int
    meas_counter: int
    interface_version: int


class ObjectGeneral(NamedTuple):
    """0x60B: one object. x forward (`dist_long_m`), y left positive (`dist_lat_m`)."""

    id: int
    dist_long_m: float
    dist_lat_m: float
    vrel_long_mps: float
    vrel_lat_mps: float
    dyn_prop: int
    rcs_dbsm: float


class ObjectQuality(NamedTuple):
    """0x60C: quality of one object; the *_rms fields are 5-bit codes (see `RMS_CODE_VALUES`)."""

    id: int
    dist_long_rms: int
    dist_lat_rms: int
    vrel_long_rms: int
    vrel_lat_rms: int
    meas_state: int
    prob_of_exist: int


class ObjectExtended(NamedTuple):
    """0x60D: extended information of one object."""

    id: int
    arel_long_mps2: float
    arel_lat_mps2: float
    obj_class: int
    orientation_deg: float
    length_m: float
    width_m: float


class ClusterListStatus(NamedTuple):
    """0x600: first frame of a cluster cycle."""

    n_near: int
    n_far: int
    meas_counter: int
    interface_version: int


class ClusterGeneral(NamedTuple):
    """0x701: one cluster (a raw detection)."""

    id: int
    dist_long_m: float
    dist_lat_m: float
    vrel_long_mps: float
    vrel_lat_mps: float
    dyn_prop: int
    rcs_dbsm: float


class ClusterQuality(NamedTuple):
    """0x702: quality of one cluster."""

    id: int
    dist_long_rms: int
    dist_lat_rms: int
    vrel_long_rms: int
    vrel_lat_rms: int
    pdh0: int
    ambig_state: int
    invalid_state: int


class RadarStateFrame(NamedTuple):
    """0x201: the radar's state and current configuration (about once a second)."""

    nvm_read_ok: int
    max_distance_m: int
    persistent_error: int
    interference: int
    temperature_error: int
    temporary_error: int
    voltage_error: int
    sensor_id: int
    sort_index: int
    motion_rx_state: int
    send_ext_info: int
    send_quality: int
    output_type: int
    rcs_threshold: int


class Version(NamedTuple):
    """0x700: firmware version."""

    major: int
    minor: int
    patch: int


class RadarConfigFrame(NamedTuple):
    """0x200 (host -> radar): a field takes effect only when its *_valid flag is 1."""

    max_distance_valid: int = 0
    sensor_id_valid: int = 0
    radar_power_valid: int = 0
    output_type_valid: int = 0
    send_quality_valid: int = 0
    send_ext_info_valid: int = 0
    sort_index_valid: int = 0
    store_in_nvm_valid: int = 0
    max_distance_m: int = 0
    sensor_id: int = 0
    output_type: int = 0
    radar_power: int = 0
    ctrl_relay_valid: int = 0
    ctrl_relay: int = 0
    send_quality: int = 0
    send_ext_info: int = 0
    sort_index: int = 0
    store_in_nvm: int = 0
    rcs_threshold_valid: int = 0
    rcs_threshold: int = 0


class SpeedInformation(NamedTuple):
    """0x300 (host -> radar): ego speed magnitude and direction (0 standstill, 1 fwd, 2 rev)."""

    direction: int
    speed_mps: float


class YawRateInformation(NamedTuple):
    """0x301 (host -> radar): ego yaw rate, left positive."""

    yaw_rate_dps: float
