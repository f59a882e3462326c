"""The AEB decision for one track, and the brake hold (pure, no I/O, no clocks).

Paper: TTC = r / |v_r| (closing only), TTC_eff = TTC - 1.0 s;
BRAKE iff verified and 3 <= r <= 25 m and TTC_eff < 2.5 s. WARNING uses the same rule
with a larger TTC_eff bound (4.0 s). Added: an in-path corridor on the lateral offset
(can be turned off), with path prediction for targets moving sideways (a crossing
pedestrian or cyclist is in the path if it will be in the corridor when the ego arrives);
a policy for tracks the camera cannot check; and a minimum hold.
"""

import math
from collections.abc import Iterable
from dataclasses import dataclass

from common.config.fusion import DecisionSettings, UnverifiablePolicy
from common.messages import Decision, RadarTrack, Verification


def severity(d: Decision) -> int:
    """NONE 0, WARNING 1, BRAKE 2."""
    return 2 if d is Decision.BRAKE else 1 if d is Decision.WARNING else 0


@dataclass(frozen=True, slots=True)
class PathWindow:
    """A sideways-moving target's prediction: inside the corridor from `enter_s` to
    `leave_s` (from now, either may be negative or infinite); the ego's front reaches
    its x after `arrival_s`."""

    enter_s: float
    leave_s: float
    arrival_s: float


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
    # Set when in_path came from the predicted sideways motion (then ttc_s = arrival).
    window: PathWindow | None = None


def corridor_window(lateral_m: float, lateral_speed_mps: float,
                    half_width_m: float) -> tuple[float, float]:
    """When a target at `lateral_m` moving sideways at constant speed is inside
    [-half_width_m, half_width_m]: (enter, leave) in seconds from now."""
    if lateral_speed_mps == 0.0:
        return (-math.inf, math.inf) if abs(lateral_m) <= half_width_m else (math.inf, math.inf)
    a = (-half_width_m - lateral_m) / lateral_speed_mps
    b = (half_width_m - lateral_m) / lateral_speed_mps
    return (a, b) if a <= b else (b, a)


class LateralMotion:
    """Which tracks move sideways: |vy| >= `min_speed_mps`, in the same direction, for
    `cycles` consecutive radar cycles. One noisy cycle of lateral velocity (a new track,
    a re-association in the radar) must not throw a stationary object into the path."""

    def __init__(self, min_speed_mps: float, cycles: int) -> None:
        self.min_speed = min_speed_mps
        self.cycles = cycles
        self._runs: dict[int, tuple[int, int]] = {}    # track id -> (direction, cycles)

    def update(self, tracks: Iterable[RadarTrack]) -> set[int]:
        """Record one radar cycle's confirmed tracks; the IDs moving sideways. Tracks
        absent from the cycle are forgotten."""
        runs: dict[int, tuple[int, int]] = {}
        moving: set[int] = set()
        lo = self.min_speed
        for t in tracks:
            vy = t.vy_mps
            direction = 1 if vy >= lo else -1 if vy <= -lo else 0
            if direction == 0:
                continue
            prev = self._runs.get(t.track_id)
            n = prev[1] + 1 if prev is not None and prev[0] == direction else 1
            runs[t.track_id] = (direction, n)
            if n >= self.cycles:
                moving.add(t.track_id)
        self._runs = runs
        return moving


class DecisionRule:
    """The rule, from the settings: each track's kinematics and the radar's threat."""

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
        p = s.corridor.prediction
        self.predict = s.corridor.enabled and p.enabled
        self.horizon = p.horizon_s
        self.arrival_margin = p.arrival_margin_s

    def kinematics(self, track: RadarTrack, moving: bool = False) -> Kinematics:
        """`moving`: the track's sideways motion is confirmed (LateralMotion)."""
        rate = track.range_rate_mps
        r = track.range_m
        lateral = track.y_m - self.centre
        vx = track.vx_mps
        if moving and self.predict and vx < 0.0:
            arrival = max(track.x_m, 0.0) / -vx
            m = self.arrival_margin
            if arrival - m <= self.horizon:
                enter, leave = corridor_window(lateral, track.vy_mps, self.corridor)
                in_path = enter <= arrival + m and leave >= max(0.0, arrival - m)
                return Kinematics(r, rate, lateral, arrival, arrival - self.offset,
                                  self.min_range <= r <= self.max_range, in_path,
                                  PathWindow(enter, leave, arrival))
        ttc = r / -rate if rate < 0.0 else None
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
        w = k.window
        if not k.in_path:
            why = "" if w is None else f"; {_window_text(w)}"
            return Decision.NONE, (f"out of corridor (lateral {k.lateral_m:+.2f} m, "
                                   f"limit {self.corridor:g} m{why})")
        where = "" if w is None else f"in path by prediction ({_window_text(w)}), "
        if k.ttc_eff_s < self.brake:
            return Decision.BRAKE, f"{where}TTC_eff {k.ttc_eff_s:.2f} s < {self.brake:g} s"
        return Decision.WARNING, f"{where}TTC_eff {k.ttc_eff_s:.2f} s < {self.warning:g} s"


def _window_text(w: PathWindow) -> str:
    return (f"in the corridor {_t(w.enter_s)} to {_t(w.leave_s)} s, "
            f"ego arrives in {w.arrival_s:.2f} s")


def _t(v: float) -> str:
    return f"{v:.2f}" if math.isfinite(v) else ("-inf" if v < 0 else "inf")


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
