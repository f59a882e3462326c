"""Configuration of a fusion (verifier) instance: the `[fusion]` table.

Defaults are what we would ship on a vehicle; `deploy/fusion-paper.toml` turns every
addition to the paper's method off. docs/fusion.md says which field is which.
"""

import enum
import re
from typing import Annotated

import msgspec

from aeb_radar_camera.common.config.base import ServiceConfig
from aeb_radar_camera.common.config.paths import ConfigPath, path_keys
from aeb_radar_camera.common.config.realtime import RealtimeSettings
from aeb_radar_camera.common.keys import EGO_MOTION, RADAR_TRACKS
from aeb_radar_camera.common.messages.radar import OBJECT_CLASSES
from aeb_radar_camera.common.resources import EXAMPLE_CALIBRATION

_CHUNK = re.compile(r"^[A-Za-z0-9_.\-]+$")
_DEFAULT_CAMERA = "front"
_DEFAULT_CALIBRATION = str(EXAMPLE_CALIBRATION)   # the shipped example

NonNegative = Annotated[float, msgspec.Meta(ge=0)]
Positive = Annotated[float, msgspec.Meta(gt=0)]
ParamValue = float | int | str | bool


class UnverifiablePolicy(enum.Enum):
    """What a threat becomes when the camera cannot check it (no usable frame, or the
    track projects outside the image)."""

    WARN = "warn"              # never brake on radar alone; raise a WARNING instead
    IGNORE = "ignore"          # as if the camera had rejected it: NONE
    RADAR_ONLY = "radar_only"  # decide on radar alone (BRAKE without the camera)


class GateScope(enum.Enum):
    CANDIDATES = "candidates"  # run the gate only where it can change the decision
    ALL = "all"                # every visible confirmed track (densities for every track)


class FrameSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Which camera, and how a frame is matched to a radar cycle."""

    camera: str = _DEFAULT_CAMERA
    # |frame capture - radar cycle| allowed; farther frames make the verifier unavailable.
    max_skew_s: Annotated[float, msgspec.Meta(gt=0, le=10)] = 0.1
    # True: the frame nearest the radar cycle, with each track predicted (constant
    # velocity) to that frame's capture time. False (paper): the newest frame, no prediction.
    align: bool = True
    # A camera whose picture has not changed (up to sensor noise) for this long while the
    # tracks moved in its image is frozen: unavailable ("camera frozen"). 0: never.
    frozen_after_s: Annotated[float, msgspec.Meta(ge=0, le=10)] = 0.5


class CameraInput(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """One of several cameras: its frames come from `camera/<name>/jpeg`, and fusion
    projects into it with its own calibration file."""

    name: str
    calibration: ConfigPath


class RoiSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    column_height_m: Positive = 2.2
    # 0: the paper's column (a vertical line at the track); > 0 widens it to a box.
    column_half_width_m: NonNegative = 0.0
    padding_px: Annotated[int, msgspec.Meta(ge=0, le=500)] = 22


class VerifierSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A verifier from the registry (services/fusion/verifiers/) and its parameters;
    parameters not given take the verifier's defaults."""

    name: str = "edge_density"
    # `weights` (hog_linear, combined) is a file, relative to the config file's folder.
    params: Annotated[dict[str, ParamValue], path_keys("weights")] = msgspec.field(
        default_factory=dict)


class PathPredictionSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A target moving sideways is in the path iff, at constant velocity, it is inside the
    corridor when the ego's front reaches it (x / closing speed along x, +- the margin);
    its TTC is then that arrival time. Targets without a confirmed sideways motion, and
    targets the ego reaches later than the horizon, are judged on their current offset."""

    enabled: bool = True
    # Predict no further than this (s): constant velocity is a guess, and lateral
    # velocity noise grows into metres.
    horizon_s: Positive = 4.0
    # Slower sideways motion is treated as none: the radar's lateral velocity is noisy
    # and would walk stationary objects beside the lane into the corridor.
    min_lateral_speed_mps: NonNegative = 0.5
    # ... and it must have lasted this many consecutive radar cycles, in one direction.
    confirm_cycles: Annotated[int, msgspec.Meta(ge=1, le=20)] = 2
    # The ego's arrival counts from this much before to this much after (s).
    arrival_margin_s: NonNegative = 0.3
    # By the radar's object class (0x60D: car, truck, pedestrian, motorcycle, bicycle,
    # point, wide): how far the object may run on behind its radar point, along its
    # sideways motion (m). The radar reports an object's nearest point, which for an
    # object coming from the side is its leading end: a car crossing at 15 km/h whose
    # front has left the path still fills it for another second. The path holds it
    # until that much behind the point has left too. A class not given, and a track
    # without one (clusters): 0.
    trailing_m: dict[str, NonNegative] = msgspec.field(default_factory=dict)

    def __post_init__(self) -> None:
        unknown = sorted(set(self.trailing_m) - set(OBJECT_CLASSES))
        if unknown:
            raise ValueError(f"trailing_m: unknown object class {', '.join(unknown)} "
                             f"(one of {', '.join(OBJECT_CLASSES)})")


class CorridorSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """In path iff |y - center_y_m| <= half_width_m + margin_m (radar frame, y left), or,
    with `prediction`, iff a sideways-moving target is there when the ego arrives."""

    enabled: bool = True
    half_width_m: NonNegative = 0.9
    margin_m: NonNegative = 0.3
    center_y_m: float = 0.0    # the vehicle's centre line in the radar frame
    prediction: PathPredictionSettings = msgspec.field(default_factory=PathPredictionSettings)


class RuleName(enum.Enum):
    """Which decision rule (docs/fusion.md, "Decision rule")."""

    PAPER = "paper"            # TTC_eff < 2.5 s in 3-25 m, straight corridor, full BRAKE
    KINEMATIC = "kinematic"    # predicted path, required deceleration, staged output


class PathSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The kinematic rule's predicted path (services/fusion/path.py): an arc of curvature
    yaw rate / speed from the radar, `half_width_m` + `margin_m` either side of it, up to
    `length_m` along it. Below `min_yaw_speed_mps` the yaw rate is mostly noise: the
    curvature comes from the steering wheel through a bicycle model when `wheelbase_m`
    is given, else the path is straight."""

    half_width_m: NonNegative = 0.9
    margin_m: NonNegative = 0.3
    # An object the point test puts in the path (its radar point within the margin) is
    # beside it when the camera's depth shows all of it farther than half_width_m +
    # camera_margin_m from the path's centre and the path's side of it empty
    # (KinematicRule.beside_path).
    camera_margin_m: NonNegative = 0.2
    # An object the point test leaves out of the path (its radar point beyond the path's
    # edge, by at most camera_into_m) is in it when the camera's depth shows its surface
    # at the radar's range running on, window by window, into the path (a car standing
    # side-on whose radar point is its far corner; KinematicRule.into_path_next). 0: off.
    camera_into_m: Annotated[float, msgspec.Meta(ge=0, le=10)] = 0.0
    length_m: Positive = 80.0
    min_yaw_speed_mps: NonNegative = 3.0
    wheelbase_m: Positive | None = None
    steering_ratio: Positive = 15.0        # steering wheel angle / road wheel angle
    # |curvature| is clipped to this (1/m): 1 / 0.05 = a 20 m radius, tighter than any
    # bend the rule is meant for.
    max_curvature_per_m: Positive = 0.05


class RoadEdgeSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The road's edge from stationary radar returns (services/fusion/road_edge.py): a
    chain of stationary tracks that starts beside the path and bends like a road the ego
    could take is the road's edge (a guard rail along a bend's outside), and its members
    with more of the chain beyond them are out of the path. Only the kinematic rule
    reads it."""

    enabled: bool = True
    # A track is stationary when its speed over ground is below this (m/s).
    stationary_mps: NonNegative = 1.0
    # The chain's nearest member: beside the path (beyond half_width_m + margin_m), at
    # most this far along it (m), ...
    start_range_m: Positive = 20.0
    # ... and its first step running along the path, within this angle (deg).
    start_heading_deg: Annotated[float, msgspec.Meta(ge=0, le=45)] = 10.0
    # Consecutive members at most this far apart (m): a rail's returns come every
    # segment (4 m in the simulator), and in a run's first cycles the tracker has not
    # yet confirmed every one (two missed in a row); a car further on is no continuation.
    max_spacing_m: Positive = 13.0
    # Each new member is fitted with the members within this length behind it
    # (a quadratic in arc length) ...
    fit_length_m: Positive = 24.0
    # ... every one of them within this of the fit (m) ...
    residual_m: NonNegative = 0.3
    # ... and the road's curvature it implies at most what gives this lateral
    # acceleration at the ego's speed (m/s^2), never beyond the path's max_curvature_per_m.
    max_lateral_mps2: Positive = 5.0
    # A chain of fewer members is none; a member is the edge only with this many beyond
    # it (the chain's end, where a car behind a rail's end would be, never is).
    min_members: Annotated[int, msgspec.Meta(ge=2, le=20)] = 3
    members_after: Annotated[int, msgspec.Meta(ge=1, le=10)] = 2


class KinematicSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The kinematic rule's bounds (`rule = "kinematic"`; docs/fusion.md).

    The deceleration a stop requires: the ego at its speed and the target at its own
    (ego speed + range rate) with its acceleration, both carried on for `latency_s`
    (radar cycle, fusion, the brake service and the actuator's and brakes' lags), then
    the ego braking at a constant deceleration so that it ends `stop_margin_m` short of
    the target. The stages compare it with their bounds; a WARNING also comes from the
    TTC with relative acceleration."""

    stop_margin_m: NonNegative = 1.0
    latency_s: Annotated[float, msgspec.Meta(ge=0, le=2)] = 0.45
    # A stage is reached when the required deceleration is at least its bound or the
    # TTC below its bound (at low speed the deceleration stays small up close).
    warning_ttc_s: Positive = 3.0
    warning_decel_mps2: Positive = 2.0
    partial_ttc_s: Positive = 2.2
    partial_decel_mps2: Positive = 3.0
    full_ttc_s: Positive = 1.6
    full_decel_mps2: Positive = 4.5
    partial_level_pct: Annotated[float, msgspec.Meta(gt=0, le=100)] = 50.0
    full_level_pct: Annotated[float, msgspec.Meta(gt=0, le=100)] = 100.0
    # The range gate: from range_min_m to range_base_m + range_time_s x ego speed, at
    # most range_max_m. Its own near bound, not the paper's 3 m: a slowly closing cyclist
    # reaches the braking stages inside 3 m (the ARS408 measures from 0.2 m).
    range_min_m: NonNegative = 0.5
    range_base_m: Positive = 15.0
    range_time_s: NonNegative = 3.5
    range_max_m: Positive = 80.0
    # The target's acceleration from its range rate, differentiated and low-pass
    # filtered with this time constant; |a| clipped to max_accel_mps2.
    accel_filter_s: Positive = 0.3
    max_accel_mps2: Positive = 10.0
    # In a bend the radar's lateral velocity of a stationary object lags its change
    # (w x shrinks as the ego nears it) by about this long: turn_lag_s x |yaw rate x
    # speed| of a track's lateral speed over ground is not taken as motion across the path.
    turn_lag_s: NonNegative = 0.8
    # The ego's turn that the radar already sees and the vehicle state does not yet (its
    # yaw rate is sampled before the radar cycle that turned, at a bend's entry or exit or
    # a steering manoeuvre): when at least unseen_turn_min_tracks tracks that stood still
    # the cycle before, each at least unseen_turn_min_range_m ahead, show a rotation of
    # the same sign beyond unseen_turn_min_rps (their median; two thirds of them agreeing),
    # those whose own apparent rotation has that sign (and at most the path's
    # max_curvature_per_m x speed) still stand: their sideways drift is the ego's turn;
    # every other track measured in the cycle takes that median turn in (a coasting
    # track's velocity is the one predicted before the turn).
    # unseen_turn_min_tracks 0: off.
    unseen_turn_min_tracks: Annotated[int, msgspec.Meta(ge=0, le=50)] = 3
    unseen_turn_min_rps: Positive = 0.01
    unseen_turn_min_range_m: NonNegative = 8.0
    # No new activation below this ego speed (a car creeping in a queue).
    min_speed_mps: NonNegative = 1.0
    # A BRAKE that brought the ego to a stop (speed <= standstill_mps) holds it at
    # standstill_level_pct for standstill_hold_s, then releases.
    standstill_mps: Positive = 0.3
    standstill_hold_s: NonNegative = 2.0
    standstill_level_pct: Annotated[float, msgspec.Meta(ge=0, le=100)] = 50.0
    # A threat the camera cannot tell yet (the verifier says unverifiable: too little
    # depth to see anything at the range, and the track's evidence sum holds no
    # confirmation): true, it is a WARNING up to the full stage and brakes at full level
    # from it, the full stage's deceleration bound raised to cannot_tell_decel_mps2 (its
    # TTC bound kept); false, it follows `unverifiable_policy`. The radar's false targets
    # at speed are decided where depth is still too sparse to tell: this brakes for them
    # only when the stop really needs it, while a threat the camera confirms keeps every
    # stage.
    cannot_tell_full_only: bool = False
    cannot_tell_decel_mps2: Positive = 5.5
    # A threat no camera's image holds (the track projects outside every image; no frame
    # at all is `unverifiable_policy`'s) and on which the track's evidence holds nothing:
    # true, it is decided as one the camera cannot tell (above); false, it follows
    # `unverifiable_policy`. The radar sees +-60 deg near, a camera of 87 deg +-43: a
    # cyclist crossing from the side is in the radar's view seconds before the camera's.
    not_visible_full_only: bool = False

    def __post_init__(self) -> None:
        if not self.warning_decel_mps2 <= self.partial_decel_mps2 <= self.full_decel_mps2:
            raise ValueError("warning_decel_mps2 <= partial_decel_mps2 <= full_decel_mps2 "
                             "required")
        if self.cannot_tell_decel_mps2 < self.full_decel_mps2:
            raise ValueError("cannot_tell_decel_mps2 must be at least full_decel_mps2")
        if not self.warning_ttc_s >= self.partial_ttc_s >= self.full_ttc_s:
            raise ValueError("warning_ttc_s >= partial_ttc_s >= full_ttc_s required")
        if self.partial_level_pct > self.full_level_pct:
            raise ValueError("partial_level_pct must not exceed full_level_pct")
        if self.range_min_m >= min(self.range_base_m, self.range_max_m):
            raise ValueError("range_min_m must be below range_base_m and range_max_m")


class OverrideSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The driver overrides the kinematic rule (`vehicle/driver`): a kick-down (the
    pedal's switch, or the pedal beyond `accelerator_pct`) or a steering manoeuvre
    (|wheel rate| >= `steering_rate_dps` or |wheel angle| >= `steering_angle_deg`)
    cancels a brake and suppresses AEB for `suppress_s` after the input ends; the
    brake pedal pressed releases AEB to the driver (the driver's braking wins). A field
    the car does not provide (None) cannot override."""

    enabled: bool = True
    accelerator_pct: Annotated[float, msgspec.Meta(gt=0, le=100)] | None = 95.0
    steering_rate_dps: Positive | None = 180.0
    steering_angle_deg: Positive | None = 90.0
    suppress_s: NonNegative = 2.0
    brake_pedal: bool = True


class VehicleInputSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """`vehicle/motion` and `vehicle/driver` (common/vehicle_state.py): fresh for
    `max_age_s` after arrival. Only the kinematic rule reads them; stale or missing, it
    is at most WARNING (docs/fusion.md, "Stale or missing vehicle state")."""

    max_age_s: Positive = EGO_MOTION.max_age_s or 0.1
    # Refuse samples whose stamp is older than max_age_s on arrival; off for hosts
    # without synchronised wall clocks.
    stamp_check: bool = True


class DecisionSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    # "paper" (the default here, so that a config without the field keeps its meaning):
    # the paper's rule, the fields up to `corridor`; "kinematic" (deploy/fusion.toml): the
    # predicted path, the required deceleration and staged output (`path`, `kinematic`,
    # `override`; the camera policy, hold and radar age as for the paper's).
    rule: RuleName = RuleName.PAPER
    min_range_m: NonNegative = 3.0
    max_range_m: Positive = 25.0
    ttc_offset_s: NonNegative = 1.0        # TTC_eff = TTC - offset
    brake_ttc_eff_s: float = 2.5           # BRAKE iff TTC_eff < this (and verified, in range)
    warning_ttc_eff_s: float = 4.0         # WARNING iff TTC_eff < this
    brake_level_pct: Annotated[float, msgspec.Meta(gt=0, le=100)] = 100.0
    hold_s: NonNegative = 1.0              # a BRAKE is kept at least this long
    unverifiable_policy: UnverifiablePolicy = UnverifiablePolicy.WARN
    # Radar cycles older than this at processing time never start a brake (~2 cycles).
    radar_max_age_s: Positive = RADAR_TRACKS.max_age_s or 0.16
    corridor: CorridorSettings = msgspec.field(default_factory=CorridorSettings)
    path: PathSettings = msgspec.field(default_factory=PathSettings)
    kinematic: KinematicSettings = msgspec.field(default_factory=KinematicSettings)
    override: OverrideSettings = msgspec.field(default_factory=OverrideSettings)
    road_edge: RoadEdgeSettings = msgspec.field(default_factory=RoadEdgeSettings)

    @property
    def range_bounds_m(self) -> tuple[float, float]:
        """The nearest and farthest range the rule decides on: the paper's
        `min_range_m`, `max_range_m`; the kinematic rule's `range_min_m` and (at speed)
        `range_max_m`."""
        if self.rule is RuleName.KINEMATIC:
            return self.kinematic.range_min_m, self.kinematic.range_max_m
        return self.min_range_m, self.max_range_m

    def __post_init__(self) -> None:
        if self.min_range_m >= self.max_range_m:
            raise ValueError("min_range_m must be below max_range_m")
        if self.warning_ttc_eff_s < self.brake_ttc_eff_s:
            raise ValueError("warning_ttc_eff_s must be at least brake_ttc_eff_s")


class EvidenceSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Evidence over time, per track: a verifier that reports a per-frame log-likelihood
    ratio of "an obstacle stands there" (`llr` in its detail: `recall_first`) has it
    summed per track id, clipped to [floor, ceiling] after each frame; the track is
    vetoed while the sum is at or below `veto_at`, else confirmed. A track with a history
    at the ceiling (or the floor) needs several frames against it to change its verdict,
    so one bad frame neither brakes nor vetoes; a new track starts at 0, where its first
    frame is all the evidence there is. Such a verifier also checks every closing track
    in range, not only the threats (after the command), so that a track that becomes a
    threat only after it has left the image is judged on what the camera saw of it.
    Verifiers without an llr (the edge-density gate) decide per frame as before."""

    enabled: bool = True
    floor: Annotated[float, msgspec.Meta(ge=-100, le=0)] = -4.0
    ceiling: Annotated[float, msgspec.Meta(ge=0, le=100)] = 4.0
    veto_at: Annotated[float, msgspec.Meta(ge=-100, lt=0)] = -1.0
    # A track not checked for this long starts again from 0 (s).
    forget_s: Annotated[float, msgspec.Meta(gt=0, le=60)] = 1.0
    # A track no frame shows (close ahead, beside the bumper) is judged on its sum so
    # far; a track the radar has just started there takes the sum of the track checked
    # last within handover_m of it in the last handover_s (the radar often re-acquires a
    # crossing cyclist under a new id as it comes close).
    handover_m: Annotated[float, msgspec.Meta(ge=0, le=20)] = 3.0
    handover_s: Annotated[float, msgspec.Meta(ge=0, le=5)] = 1.0

    def __post_init__(self) -> None:
        if self.veto_at < self.floor:
            raise ValueError("veto_at must not be below floor (nothing could be vetoed)")


class FusionSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    # Every key this instance publishes is under fusion/<instance>/.
    instance: str = "primary"
    radar_sensor: str = "front"
    # Calibration TOML (common/calibration.py), relative to this config file's folder.
    calibration: ConfigPath = _DEFAULT_CALIBRATION
    gate_scope: GateScope = GateScope.CANDIDATES
    frames: FrameSettings = msgspec.field(default_factory=FrameSettings)
    roi: RoiSettings = msgspec.field(default_factory=RoiSettings)
    verifier: VerifierSettings = msgspec.field(default_factory=VerifierSettings)
    decision: DecisionSettings = msgspec.field(default_factory=DecisionSettings)
    evidence: EvidenceSettings = msgspec.field(default_factory=EvidenceSettings)
    vehicle_state: VehicleInputSettings = msgspec.field(default_factory=VehicleInputSettings)
    stats_interval_s: Positive = 10.0      # how often counters are logged
    # At most one radar cycle (one BrakeCommand) per this interval, whatever arrives on
    # radar/<sensor>/tracks: extra cycles are shed (counted `tracks_shed`), the newest
    # one in the interval is decided at its end. The radar's cycle is 75 ms; 0: no bound.
    min_cycle_interval_s: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.05
    # Several cameras, each with its own calibration, instead of `frames.camera` and
    # `calibration` (leave those out). A track is verified if any camera that sees it
    # verifies it (docs/fusion.md). `frames` settings apply to every camera.
    cameras: Annotated[tuple[CameraInput, ...], msgspec.Meta(max_length=8)] = ()
    # SCHED_FIFO for the radar callback (decide, publish) and the Zenoh I/O threads
    realtime: RealtimeSettings = msgspec.field(default_factory=RealtimeSettings)
    # Key file of this instance (`aeb keygen`; common/command_auth.py): every BrakeCommand
    # is signed with it. Empty: unsigned commands, which no brake follows (shadow mode).
    command_key: ConfigPath = ""

    def __post_init__(self) -> None:
        names = [c.name for c in self.cameras]
        fields = [("instance", self.instance), ("radar_sensor", self.radar_sensor),
                  ("frames.camera", self.frames.camera)]
        fields += [(f"cameras[{i}].name", n) for i, n in enumerate(names)]
        for field, value in fields:
            if not _CHUNK.match(value):
                raise ValueError(f"{field} {value!r} must be letters, digits, '_', '-' or '.'")
        if not self.calibration or any(not c.calibration for c in self.cameras):
            raise ValueError("calibration must name a calibration TOML file")
        if len(set(names)) != len(names):
            raise ValueError(f"cameras: duplicate camera name in {names}")
        if self.cameras and (self.frames.camera != _DEFAULT_CAMERA
                             or self.calibration != _DEFAULT_CALIBRATION):
            raise ValueError("give either frames.camera and calibration (one camera) or "
                             "[[fusion.cameras]], not both")

    @property
    def camera_inputs(self) -> tuple[CameraInput, ...]:
        """Every camera this instance verifies with, in the order they are tried."""
        return self.cameras or (CameraInput(self.frames.camera, self.calibration),)


class FusionConfig(ServiceConfig, frozen=True, forbid_unknown_fields=True):
    fusion: FusionSettings = msgspec.field(default_factory=FusionSettings)
