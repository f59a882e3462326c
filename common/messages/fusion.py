"""Messages published by a fusion (verifier) instance."""

import enum

import msgspec

from aeb_radar_camera.common.messages.header import Header


class Decision(enum.Enum):
    """Ordered by severity: NONE < WARNING < BRAKE."""

    NONE = "NONE"
    WARNING = "WARNING"
    BRAKE = "BRAKE"


class Verification(enum.Enum):
    VERIFIED = "verified"          # density >= threshold
    REJECTED = "rejected"          # density below threshold
    NOT_VISIBLE = "not_visible"    # behind the camera or outside the image
    UNAVAILABLE = "unavailable"    # no usable frame (stale, missing, undecodable)
    NOT_CHECKED = "not_checked"    # out of the decision's range: the gate did not run


class VerifierStatus(enum.Enum):
    OK = "ok"
    UNAVAILABLE = "unavailable"    # no fresh decodable frame
    STALE_RADAR = "stale_radar"    # radar input older than allowed: never brakes


class CameraCheck(msgspec.Struct, frozen=True, gc=False):
    """One camera's view of a track, in instances with several cameras. `not_checked`
    here also means a camera after the one that verified the track (not gated)."""

    camera: str
    verification: Verification
    roi_xywh: tuple[int, ...] = ()
    density: float | None = None


class VerifiedTarget(msgspec.Struct, frozen=True, gc=False, kw_only=True):
    """One confirmed radar track after verification and decision.

    `x_m`, `y_m` are the track predicted to the frame's capture time (what was projected;
    the prediction interval is -`frame_age_ms`). `range_m` and `range_rate_mps` are the
    radar cycle's own values (what the decision used). `roi_xywh` is in pixels of the
    frame, empty when not visible or not projected. `gate_detail` holds what a verifier
    derived for this ROI (e.g. adapted thresholds), empty for fixed-parameter verifiers.
    `density` is the verifier's score (named so on the wire since the paper's gate, whose
    score is the edge density); `score_name` says what it is for this verifier
    ("edge_density", "depth_share", "probability", ...; empty in recordings made before
    it existed, where it was the verifier's score as well).
    `path_predicted`: `in_path` was decided from the track's sideways motion (is it in
    the corridor when the ego arrives?), and `ttc_s` is the time the ego's front reaches
    it (x / closing speed along x), not r / |range rate|.

    With several cameras, `camera` is the camera whose verdict decided (the first that
    verified; else the rejecting one with the highest density; empty when none sees the
    track), and `roi_xywh`, `density`, `frame_seq`, `frame_age_ms`, `x_m`, `y_m` are that
    camera's; `cameras` lists every camera's own check. With one camera `cameras` is empty.
    """

    track_id: int
    x_m: float
    y_m: float
    range_m: float
    range_rate_mps: float
    in_path: bool
    verification: Verification
    roi_xywh: tuple[int, ...]
    density: float | None
    ttc_s: float | None            # None when not closing
    ttc_eff_s: float | None
    decision: Decision
    reason: str                    # why this decision, for people and logs
    frame_seq: int | None
    frame_age_ms: float | None     # radar cycle stamp - frame capture (negative: newer frame)
    gate_detail: dict[str, float] = msgspec.field(default_factory=dict)
    path_predicted: bool = False
    camera: str = ""
    cameras: tuple[CameraCheck, ...] = ()
    score_name: str = ""
    # The kinematic rule's figures (None under the paper's rule): the level of the
    # track's BRAKE stage, the deceleration a stop requires (inf: the gap is gone within
    # the latency), the target's acceleration over ground along the path, and where it
    # is on the path (arc length, offset; left positive).
    brake_level_pct: float | None = None
    required_decel_mps2: float | None = None
    accel_mps2: float | None = None
    path_s_m: float | None = None
    path_d_m: float | None = None


class VerifiedTargets(msgspec.Struct, frozen=True, gc=False, kw_only=True):
    header: Header
    instance: str
    radar_sensor: str
    radar_seq: int
    verifier: str
    verifier_params: dict[str, float | int | str | bool]
    verifier_status: VerifierStatus
    targets: tuple[VerifiedTarget, ...]
    processing_ns: int             # tracks received -> decision made
    camera: str = ""
    unavailable_reason: str = ""   # why the verifier is unavailable, empty when OK
    radar_age_ms: float | None = None  # radar cycle stamp -> processing (wall clocks)
    frames_received: int = 0       # camera frames seen by this instance since start
    frames_undecodable: int = 0    # ... of which could not be decoded (counted, skipped)
    frames_dropped: int = 0        # ... dropped before decoding because the decoder lagged
    # Always 0: fusion decodes every frame it receives. Kept on the wire: removing a field
    # is a breaking change (common/messages/schema.py).
    frames_skipped: int = 0
    frames_corrupt: int = 0        # ... of the undecodable: JPEG bytes failing their CRC-32
    # Cameras without a usable frame this cycle, and why (the others verified as usual).
    cameras_unavailable: dict[str, str] = msgspec.field(default_factory=dict)
    # The vehicle's state as the kinematic rule used it (None / empty under the paper's
    # rule): ego speed and yaw rate, the path, why the state was not usable (empty when
    # fresh: the degraded mode, at most WARNING), the driver's override in force.
    ego_speed_mps: float | None = None
    ego_yaw_rate_dps: float | None = None
    path: str = ""
    vehicle_state: str = ""
    override: str = ""
    # ... and the path it judged by: the arc's curvature (1/m, left positive; 0: straight)
    # and the range gate's far end this cycle (m), for views that draw it
    path_curvature_per_m: float | None = None
    range_gate_m: float | None = None


class CommandAuth(msgspec.Struct, frozen=True, gc=False):
    """Who made a BrakeCommand (common/command_auth.py, docs/security.md).

    `mac` is keyed BLAKE2b (32 bytes), with the key `key_id` names, over the encoded
    command up to the MAC's own 32 bytes, which are the last 32 bytes of the payload: it
    covers every other field, the sequence number, the stamps and `session` (random per
    fusion process start) included."""

    key_id: str
    session: int
    mac: bytes


class BrakeCommand(msgspec.Struct, frozen=True, gc=False, kw_only=True):
    """Exactly one per radar cycle per fusion instance: the most severe decision, or a
    plain heartbeat (decision NONE, level 0).

    `header.seq` increases by one per command of this instance; `header.stamp_ns` is the
    radar cycle's stamp. `radar_last_frame_mono_ns` carries the radar host's monotonic
    time of the cycle's last CAN frame so that a same-host receiver can measure the whole
    chain.
    """

    header: Header
    instance: str
    decision: Decision
    brake_level_pct: float         # 0..100; 0 unless decision is BRAKE
    verifier_status: VerifierStatus
    held: bool                     # BRAKE kept by the minimum-hold rule, not by this cycle
    track_id: int                  # the deciding track, -1 when none
    range_m: float | None
    ttc_s: float | None
    reason: str
    radar_seq: int
    radar_last_frame_mono_ns: int
    # The driver's override in force (kinematic rule): ``kick-down``, ``steering`` (AEB
    # suppressed), ``brake pedal`` (AEB released to the driver); empty when none.
    override: str = ""
    # Last, so that the MAC is the payload's last bytes; None: unsigned (never followed)
    auth: CommandAuth | None = None
