"""The AEB decision for one track, and the brake hold (pure, no I/O, no clocks).

Paper: TTC = r / |v_r| (closing only), TTC_eff = TTC - 1.0 s;
BRAKE iff verified and 3 <= r <= 25 m and TTC_eff < 2.5 s. WARNING uses the same rule
with a larger TTC_eff bound (4.0 s). Added: an in-path corridor on the lateral offset
(can be turned off), a policy for tracks the camera cannot check, and a minimum hold.
"""

from dataclasses import dataclass

from common.config.fusion import DecisionSettings, UnverifiablePolicy
from common.messages import Decision, RadarTrack, Verification

SEVERITY = {Decision.NONE: 0, Decision.WARNING: 1, Decision.BRAKE: 2}


@dataclass(frozen=True, slots=True)
class Kinematics:
    range_m: float
    range_rate_mps: float
    lateral_m: float          # offset from the vehicle's centre line (left positive)
    ttc_s: float | None       # None when not closing
    ttc_eff_s: float | None
    in_range: bool
    in_path: bool             # always True when the corridor check is off


def kinematics(track: RadarTrack, s: DecisionSettings) -> Kinematics:
    closing = track.range_rate_mps < 0.0
    ttc = track.range_m / -track.range_rate_mps if closing else None
    lateral = track.y_m - s.corridor.center_y_m
    corridor = s.corridor.half_width_m + s.corridor.margin_m
    return Kinematics(
        range_m=track.range_m,
        range_rate_mps=track.range_rate_mps,
        lateral_m=lateral,
        ttc_s=ttc,
        ttc_eff_s=None if ttc is None else ttc - s.ttc_offset_s,
        in_range=s.min_range_m <= track.range_m <= s.max_range_m,
        in_path=not s.corridor.enabled or abs(lateral) <= corridor,
    )


def radar_threat(k: Kinematics, s: DecisionSettings) -> tuple[Decision, str]:
    """What the radar alone asks for, before the camera: NONE, WARNING or BRAKE."""
    if not k.in_range:
        return Decision.NONE, (f"range {k.range_m:.2f} m outside "
                               f"[{s.min_range_m:g}, {s.max_range_m:g}] m")
    if k.ttc_eff_s is None:
        return Decision.NONE, f"not closing (range rate {k.range_rate_mps:+.2f} m/s)"
    if k.ttc_eff_s >= s.warning_ttc_eff_s:
        return Decision.NONE, f"TTC_eff {k.ttc_eff_s:.2f} s >= {s.warning_ttc_eff_s:g} s"
    if not k.in_path:
        limit = s.corridor.half_width_m + s.corridor.margin_m
        return Decision.NONE, (f"out of corridor (lateral {k.lateral_m:+.2f} m, "
                               f"limit {limit:g} m)")
    if k.ttc_eff_s < s.brake_ttc_eff_s:
        return Decision.BRAKE, f"TTC_eff {k.ttc_eff_s:.2f} s < {s.brake_ttc_eff_s:g} s"
    return Decision.WARNING, f"TTC_eff {k.ttc_eff_s:.2f} s < {s.warning_ttc_eff_s:g} s"


def decide(threat: Decision, threat_reason: str, verification: Verification,
           policy: UnverifiablePolicy) -> tuple[Decision, str]:
    """Combine the radar's threat with the camera's verdict."""
    if threat is Decision.NONE:
        return Decision.NONE, threat_reason
    if verification is Verification.VERIFIED:
        return threat, f"verified, {threat_reason}"
    if verification is Verification.REJECTED:
        return Decision.NONE, f"camera rejected ({threat_reason})"
    if verification in (Verification.UNAVAILABLE, Verification.NOT_VISIBLE):
        what = verification.value.replace("_", " ")
        if policy is UnverifiablePolicy.RADAR_ONLY:
            return threat, f"camera {what}, radar only: {threat_reason}"
        if policy is UnverifiablePolicy.WARN:
            return Decision.WARNING, f"camera {what}, warn only: {threat_reason}"
        return Decision.NONE, f"camera {what}, ignored: {threat_reason}"
    return Decision.NONE, f"gate did not run ({threat_reason})"


class BrakeHold:
    """Keeps a BRAKE for at least `hold_ns` after the last cycle that decided it."""

    def __init__(self, hold_ns: int) -> None:
        self.hold_ns = hold_ns
        self.until_ns: int | None = None
        self.track_id = -1

    def update(self, decision: Decision, track_id: int, now_ns: int) -> bool:
        """Record this cycle's decision; True when a BRAKE must be held despite it."""
        if decision is Decision.BRAKE:
            if self.hold_ns > 0:
                self.until_ns = now_ns + self.hold_ns
                self.track_id = track_id
            return False
        if self.until_ns is not None and now_ns < self.until_ns:
            return True
        self.until_ns = None
        return False

    def remaining_ns(self, now_ns: int) -> int:
        return 0 if self.until_ns is None else max(0, self.until_ns - now_ns)
