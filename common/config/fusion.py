"""Configuration of a fusion (verifier) instance: the `[fusion]` table.

Defaults are what we would ship on a vehicle; `deploy/fusion-paper.toml` turns every
addition to the paper's method off. docs/fusion.md says which field is which.
"""

import enum
import re
from typing import Annotated

import msgspec

from common.config.base import ServiceConfig
from common.config.paths import ConfigPath, path_keys
from common.config.realtime import RealtimeSettings
from common.keys import RADAR_TRACKS
from common.resources import EXAMPLE_CALIBRATION

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


class CorridorSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """In path iff |y - center_y_m| <= half_width_m + margin_m (radar frame, y left), or,
    with `prediction`, iff a sideways-moving target is there when the ego arrives."""

    enabled: bool = True
    half_width_m: NonNegative = 0.9
    margin_m: NonNegative = 0.3
    center_y_m: float = 0.0    # the vehicle's centre line in the radar frame
    prediction: PathPredictionSettings = msgspec.field(default_factory=PathPredictionSettings)


class DecisionSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
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
    frame is all the evidence there is. Verifiers without an llr (the edge-density gate)
    decide per frame as before."""

    enabled: bool = True
    floor: Annotated[float, msgspec.Meta(ge=-100, le=0)] = -4.0
    ceiling: Annotated[float, msgspec.Meta(ge=0, le=100)] = 4.0
    veto_at: Annotated[float, msgspec.Meta(ge=-100, lt=0)] = -1.0
    # A track not checked for this long starts again from 0 (s).
    forget_s: Annotated[float, msgspec.Meta(gt=0, le=60)] = 1.0

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
