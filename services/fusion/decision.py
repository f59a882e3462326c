"""The AEB decision for one track, and the brake hold (pure, no I/O, no clocks).

Paper: TTC = r / |v_r| (closing only), TTC_eff = TTC - 1.0 s;
BRAKE iff verified and 3 <= r <= 25 m and TTC_eff < 2.5 s. WARNING uses the same rule
with a larger TTC_eff bound (4.0 s). Added: an in-path corridor on the lateral offset
(can be turned off), a policy for tracks the camera cannot check, and a minimum hold.
"""

from dataclasses import dataclass

from common.config.fusion import DecisionSettings, UnverifiablePolicy
from common.messages import Decision, RadarTrack, Verification


def severity(d: Decision) -> int:
    """NONE 0, WARNING 1, BRAKE 2 (identity tests: much cheaper than hashing an enum)."""
    return 2 if d is Decision.BRAKE else 1 if d is Decision.WARNING else 0


@dataclass(frozen=True, slots=True)
class Kinematics:
    """A track's range, closing and lateral figures as the decision sees them."""

    range_m: float
    range_rate_mps: float
    lateral_m: float          # offset from the vehicle's centre line (left positive)
    ttc_s: float | None       # None when not closing
    ttc_eff_s: float | None
    in_range: bool
    in_path: bool             # always True when the corridor check is off


class DecisionRule:
    """The settings' numbers, read once: this runs for every track of every cycle."""

    def __init__(self, s: DecisionSettings) -> None:
        self.min_range = s.min_range_m
        self.max_range = s.max_range_m
        self.offset = s.ttc_offset_s
        self.brake = s.brake_ttc_eff_s
        self.warning = s.warning_ttc_eff_s
        self.corridor_on = s.corridor.enabled
        self.centre = s.corridor.center_y_m
        self.corridor = s.corridor.half_width_m + s.corridor.margin_m
        self.policy = s.unverifiable_policy

    def kinematics(self, track: RadarTrack) -> Kinematics:
        rate = track.range_rate_mps
        r = track.range_m
        ttc = r / -rate if rate < 0.0 else None
        lateral = track.y_m - self.centre
        return Kinematics(
            r, rate, lateral, ttc, None if ttc is None else ttc - self.offset,
            self.min_range <= r <= self.max_range,
            not self.corridor_on or abs(lateral) <= self.corridor)

    def threat(self, k: Kinematics) -> tuple[Decision, str]:
        """What the radar alone asks for, before the camera: NONE, WARNING or BRAKE."""
        if not k.in_range:
            return Decision.NONE, (f"range {k.range_m:.2f} m outside "
                                   f"[{self.min_range:g}, {self.max_range:g}] m")
        if k.ttc_eff_s is None:
            return Decision.NONE, f"not closing (range rate {k.range_rate_mps:+.2f} m/s)"
        if k.ttc_eff_s >= self.warning:
            return Decision.NONE, f"TTC_eff {k.ttc_eff_s:.2f} s >= {self.warning:g} s"
        if not k.in_path:
            return Decision.NONE, (f"out of corridor (lateral {k.lateral_m:+.2f} m, "
                                   f"limit {self.corridor:g} m)")
        if k.ttc_eff_s < self.brake:
            return Decision.BRAKE, f"TTC_eff {k.ttc_eff_s:.2f} s < {self.brake:g} s"
        return Decision.WARNING, f"TTC_eff {k.ttc_eff_s:.2f} s < {self.warning:g} s"


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
