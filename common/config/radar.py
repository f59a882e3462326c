"""Configuration of the radar service (`aeb radar --config FILE`): the ``[radar]`` table.

Every number of the paper's radar stage is here with the paper's value as default
(prefilter: forward, 0 < range <= 25 m, RCS > -20 dBsm; confirmation after 3 consecutive
updates). See docs/radar.md for each field.
"""

import enum
import re
from typing import Annotated

import msgspec

from aeb_radar_camera.common.config.base import ServiceConfig
from aeb_radar_camera.common.config.can import REPLAY, CanSettings, ReplaySettings
from aeb_radar_camera.common.config.can import Pace as Pace  # the radar's users import it from here
from aeb_radar_camera.common.config.realtime import RealtimeSettings

_NAME = re.compile(r"^[A-Za-z0-9_\-]+$")

PositiveFloat = Annotated[float, msgspec.Meta(gt=0)]
NonNegFloat = Annotated[float, msgspec.Meta(ge=0)]
PositiveInt = Annotated[int, msgspec.Meta(ge=1)]


class Expect(enum.Enum):
    """Does a cycle carry quality / extended frames? Learned from the stream (auto), or fixed."""

    AUTO = "auto"
    YES = "yes"
    NO = "no"


class OutputTypeCfg(enum.Enum):
    OBJECTS = "objects"
    CLUSTERS = "clusters"


class RadarWriteSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Write the radar configuration (0x200) at start and confirm it from 0x201.

    The SensorID is never written (a wrong one would move the radar to other IDs)."""

    enabled: bool = False
    output_type: OutputTypeCfg = OutputTypeCfg.OBJECTS
    max_distance_m: Annotated[int, msgspec.Meta(ge=90, le=1022, multiple_of=2)] = 200
    send_quality: bool = True
    send_ext_info: bool = True
    sort_index: Annotated[int, msgspec.Meta(ge=0, le=2)] = 1       # 0 none, 1 range, 2 RCS
    rcs_threshold: Annotated[int, msgspec.Meta(ge=0, le=1)] = 0    # 1: high sensitivity
    radar_power: Annotated[int, msgspec.Meta(ge=0, le=3)] | None = None   # None: not written
    store_in_nvm: bool = False
    confirm_timeout_s: PositiveFloat = 3.0     # 0x201 comes about once a second
    attempts: PositiveInt = 3


class SensorSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """One radar on the bus; publishes under ``radar/<name>/...``."""

    name: str = "front"
    sensor_id: Annotated[int, msgspec.Meta(ge=0, le=7)] = 0
    configure: RadarWriteSettings = msgspec.field(default_factory=RadarWriteSettings)

    def __post_init__(self) -> None:
        if not _NAME.match(self.name):
            raise ValueError(f"sensor name {self.name!r} must be letters, digits, '_' or '-'")


class CycleSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    expect_quality: Expect = Expect.AUTO
    expect_extended: Expect = Expect.AUTO
    timeout_s: PositiveFloat = 0.2   # an open cycle older than this is closed as incomplete


class PrefilterSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Paper: forward targets only, 0 < range <= 25 m, RCS > -20 dBsm."""

    forward_only: bool = True              # x > 0
    min_range_m: NonNegFloat = 0.0         # exclusive
    max_range_m: PositiveFloat = 25.0      # inclusive
    min_rcs_dbsm: float = -20.0            # exclusive
    min_prob_of_exist: Annotated[int, msgspec.Meta(ge=0, le=7)] = 0   # objects, 0x60C code
    drop_cluster_invalid_states: tuple[int, ...] = ()                  # clusters, 0x702 codes

    def __post_init__(self) -> None:
        if self.max_range_m <= self.min_range_m:
            raise ValueError("prefilter.max_range_m must be above min_range_m")


class MergeSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Detections within `distance_m` of a seed (the strongest unmerged one) whose velocity
    differs by at most `velocity_mps` merge into their centroid."""

    enabled: bool = True
    distance_m: PositiveFloat = 1.5
    velocity_mps: PositiveFloat = 1.0


class TrackerSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Constant-velocity Kalman filter on [x, y, vx, vy]; measurements [x, y, vx, vy]."""

    confirm_hits: PositiveInt = 3              # consecutive cycles with a detection
    delete_after_misses: PositiveInt = 3       # confirmed tracks: consecutive misses
    delete_tentative_after_misses: PositiveInt = 1
    accel_std_mps2: PositiveFloat = 3.0        # process noise (white acceleration)
    pos_x_std_m: PositiveFloat = 0.3
    pos_y_std_m: PositiveFloat = 0.5
    vel_x_std_mps: PositiveFloat = 0.4
    vel_y_std_mps: PositiveFloat = 1.0
    gate_chi2: PositiveFloat = 13.28           # 99 % for 4 degrees of freedom
    gate_max_distance_m: PositiveFloat = 3.0   # hard cap, whatever the covariance
    # A confirmed track without a match re-acquires an unmatched detection inside this
    # position-only gate (99 % for 2 degrees of freedom) with the detection's velocity,
    # keeping its ID (a target that set off or stopped abruptly); 0: off
    reacquire_chi2: NonNegFloat = 9.21
    # ... whose velocity differs by at most this from the track's: a pedestrian or a
    # cyclist setting off from a standstill (up to 20 km/h); a larger jump within one
    # cycle is another object (a post beside a car ahead whose own return was missed)
    reacquire_max_dv_mps: PositiveFloat = 6.0
    radar_id_bonus: NonNegFloat = 3.0          # cost reduction when the radar's ID matches
    drop_receding: bool = False                # do not publish tracks moving away
    receding_min_mps: NonNegFloat = 0.5        # range rate above this = receding
    max_gap_s: PositiveFloat = 0.5             # a longer gap between cycles resets the tracker


class EgoMotionSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Forward `vehicle/motion` (EgoMotion) to every radar as 0x300 / 0x301."""

    forward: bool = False
    min_interval_s: NonNegFloat = 0.02     # at most 50 Hz on the bus
    max_age_s: PositiveFloat = 0.2         # older samples are not forwarded


class RawCanSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Publish every received CAN frame on `can/<bus>/frames` (RawCanFrames), so that a
    recording can re-run the radar's decoding and tracking (`aeb rerun radar`)."""

    publish: bool = False
    bus: str = "radar"         # the key's name for this bus

    def __post_init__(self) -> None:
        if not _NAME.match(self.bus):
            raise ValueError(f"raw_can.bus {self.bus!r} must be letters, digits, '_' or '-'")


class RadarSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    can: CanSettings = msgspec.field(default_factory=CanSettings)
    replay: ReplaySettings = msgspec.field(default_factory=ReplaySettings)
    sensors: tuple[SensorSettings, ...] = (SensorSettings(),)
    cycle: CycleSettings = msgspec.field(default_factory=CycleSettings)
    prefilter: PrefilterSettings = msgspec.field(default_factory=PrefilterSettings)
    merge: MergeSettings = msgspec.field(default_factory=MergeSettings)
    tracker: TrackerSettings = msgspec.field(default_factory=TrackerSettings)
    ego_motion: EgoMotionSettings = msgspec.field(default_factory=EgoMotionSettings)
    status_period_s: PositiveFloat = 1.0
    stats_period_s: NonNegFloat = 10.0    # a radar_stats log line per radar this often (0: never)
    raw_can: RawCanSettings = msgspec.field(default_factory=RawCanSettings)
    # SCHED_FIFO for the CAN loop (decode, track, publish) and the Zenoh I/O threads
    realtime: RealtimeSettings = msgspec.field(default_factory=RealtimeSettings)

    def __post_init__(self) -> None:
        if not self.sensors:
            raise ValueError("radar.sensors must list at least one radar")
        names = [s.name for s in self.sensors]
        ids = [s.sensor_id for s in self.sensors]
        if len(set(names)) != len(names):
            raise ValueError(f"radar.sensors: duplicate names {names}")
        if len(set(ids)) != len(ids):
            raise ValueError(f"radar.sensors: duplicate sensor_id {ids}")
        if self.can.interface == REPLAY and not self.replay.file:
            raise ValueError("can.interface = 'replay' needs replay.file")


class RadarConfig(ServiceConfig, frozen=True, forbid_unknown_fields=True):
    radar: RadarSettings = msgspec.field(default_factory=RadarSettings)
