"""The AEB decision for one track, and the brake hold (pure, no I/O, no clocks).

Two rules (`[fusion.decision] rule`): the paper's (`DecisionRule`, below) and the
kinematic one (`KinematicRule`: the predicted path, the TTC with the target's
acceleration, the deceleration a stop requires, staged output, driver override;
docs/fusion.md, "Decision rule").

Paper: TTC = r / |v_r| (closing only), TTC_eff = TTC - 1.0 s;
BRAKE iff verified and 3 <= r <= 25 m and TTC_eff < 2.5 s. WARNING uses the same rule
with a larger TTC_eff bound (4.0 s). Added: an in-path corridor on the lateral offset
(can be turned off), with path prediction for targets moving sideways (a crossing
pedestrian or cyclist is in the path if it will be in the corridor when the ego arrives);
a policy for tracks the camera cannot check; and a minimum hold.
"""

import math
import statistics
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace

import msgspec

from aeb_radar_camera.common.config.fusion import (
    DecisionSettings,
    PathPredictionSettings,
    UnverifiablePolicy,
)
from aeb_radar_camera.common.messages import Decision, RadarTrack, Verification
from aeb_radar_camera.common.messages.radar import OBJECT_CLASSES
from aeb_radar_camera.common.vehicle_state import VehicleSample
from aeb_radar_camera.services.fusion.evidence import (
    AT_Y_MAX,
    AT_Y_MIN,
    THROUGH_HIGH_Y,
    THROUGH_LOW_Y,
    WINDOW_Y_MAX,
    WINDOW_Y_MIN,
)
from aeb_radar_camera.services.fusion.path import (
    PathPoint,
    PredictedPath,
    predicted_path,
    straight_path,
)
from aeb_radar_camera.services.fusion.road_edge import EdgePoint, on_edge, road_edges


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
    # The kinematic rule's figures (None under the paper's rule):
    level_pct: float | None = None           # the brake level of its BRAKE stage
    required_decel_mps2: float | None = None
    accel_mps2: float | None = None          # the target's along the path (over ground)
    path_point: PathPoint | None = None
    # Why the point test's in-path track is out of it as the road's edge ("": it is not).
    road_edge: str = ""
    # Why the camera put a track the point test leaves out of the path in it ("": it did
    # not; fusion's into-path memory).
    by_camera: str = ""
    # The radar point lies in the path's margin (beyond the vehicle's half-width) and was
    # out of the path the radar cycle before: the partial stage waits for a second cycle.
    margin_first: bool = False


def corridor_window(lateral_m: float, lateral_speed_mps: float,
                    half_width_m: float) -> tuple[float, float]:
    """When a target at `lateral_m` moving sideways at constant speed is inside
    [-half_width_m, half_width_m]: (enter, leave) in seconds from now."""
    if lateral_speed_mps == 0.0:
        return (-math.inf, math.inf) if abs(lateral_m) <= half_width_m else (math.inf, math.inf)
    a = (-half_width_m - lateral_m) / lateral_speed_mps
    b = (half_width_m - lateral_m) / lateral_speed_mps
    return (a, b) if a <= b else (b, a)


def crossing_window(lateral_m: float, lateral_speed_mps: float, half_width_m: float,
                    trailing_m: float) -> tuple[float, float]:
    """As corridor_window for an object that runs on `trailing_m` behind its point along
    its sideways motion: from its point's entering to its trailing end's leaving."""
    enter, leave = corridor_window(lateral_m, lateral_speed_mps, half_width_m)
    if trailing_m > 0.0 and lateral_speed_mps != 0.0:
        tail = lateral_m - math.copysign(trailing_m, lateral_speed_mps)
        leave = max(leave, corridor_window(tail, lateral_speed_mps, half_width_m)[1])
    return enter, leave


def trailing_lengths(p: PathPredictionSettings) -> dict[int, float]:
    """`trailing_m` by the radar's object class code."""
    return {OBJECT_CLASSES.index(name): m for name, m in p.trailing_m.items()}


def unseen_turn(ratios: Sequence[float], min_tracks: int, min_rps: float) -> float:
    """The rotation (rad/s) that stationary points' sideways drift over their range
    (`ratios`, one per point: -vy / x) shows: their median, when there are at least
    `min_tracks` of them, it is at least `min_rps` and two thirds of them drift that way
    by at least `min_rps`; else 0.0."""
    if len(ratios) < max(min_tracks, 1):
        return 0.0
    med = statistics.median(ratios)
    if abs(med) < min_rps:
        return 0.0
    agree = sum(1 for r in ratios if r * med > 0.0 and abs(r) >= min_rps)
    return med if 3 * agree >= 2 * len(ratios) else 0.0


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
        self.trailing = trailing_lengths(p)

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
                enter, leave = crossing_window(lateral, track.vy_mps, self.corridor,
                                               self.trailing.get(track.obj_class, 0.0))
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

    def clear(self) -> None:
        """End a hold now (the driver took over, the ego stood still long enough)."""
        self.until_ns = None


# -- the kinematic rule (rule = "kinematic") ------------------------------------------------


def time_to_collision(gap_m: float, ego_mps: float, lead_mps: float,
                      lead_decel_mps2: float) -> float | None:
    """When the ego at constant speed reaches a target `gap_m` ahead that moves at
    `lead_mps` along the path and brakes at `lead_decel_mps2` (>= 0) to a stop; None
    when never. A gap of 0 or less is now (0)."""
    if gap_m <= 0.0:
        return 0.0
    closing = ego_mps - lead_mps
    a = lead_decel_mps2 if lead_mps > 0.0 else 0.0
    if a <= 0.0:
        return gap_m / closing if closing > 0.0 else None
    t = (-closing + math.sqrt(max(closing * closing + 2.0 * a * gap_m, 0.0))) / a
    stop_t = lead_mps / a
    if t <= stop_t:
        return t
    # The target stops first, lead^2 / 2a further on.
    if ego_mps <= 0.0:
        return None
    return (gap_m + lead_mps * lead_mps / (2.0 * a)) / ego_mps


def required_decel(gap_m: float, ego_mps: float, lead_mps: float, lead_decel_mps2: float,
                   latency_s: float) -> float:
    """The constant deceleration the ego needs, starting after `latency_s` at its speed,
    so that it never closes the `gap_m` to a target at `lead_mps` braking at
    `lead_decel_mps2` (>= 0) to a stop. 0 when no braking is needed, inf when the gap is
    gone before the brake acts."""
    a = lead_decel_mps2 if lead_mps > 0.0 else 0.0
    t = latency_s
    if a > 0.0:
        tl = min(t, lead_mps / a)
        lead_travel = lead_mps * tl - 0.5 * a * tl * tl
        lead_after = lead_mps - a * tl
    else:
        lead_travel = lead_mps * t
        lead_after = lead_mps
    gap = gap_m + lead_travel - ego_mps * t
    if gap <= 0.0:
        return math.inf if ego_mps > 0.0 else 0.0
    closing = ego_mps - lead_after
    if a > 0.0 and lead_after > 0.0:
        # Either the ego matches the target's speed while the target still moves ...
        if closing > 0.0 and 2.0 * gap / closing <= lead_after / a:
            return a + closing * closing / (2.0 * gap)
        # ... or it stops behind where the target stops.
        return max(ego_mps, 0.0) ** 2 / (2.0 * (gap + lead_after * lead_after / (2.0 * a)))
    return closing * closing / (2.0 * gap) if closing > 0.0 else 0.0


class LeadAcceleration:
    """Each track's acceleration over ground along the path: the derivative of its speed
    (ego speed + range rate), low-pass filtered with time constant `tau_s`, clipped to
    +-`limit`. A track's first cycle, or one after a gap longer than `max_gap_s`, has
    none yet (0: constant speed). Tracks absent from a cycle are forgotten."""

    def __init__(self, tau_s: float, limit_mps2: float, max_gap_s: float = 0.5) -> None:
        self.tau_s = tau_s
        self.limit = limit_mps2
        self.max_gap_ns = round(max_gap_s * 1e9)
        self._state: dict[int, tuple[int, float, float]] = {}   # id -> (t_ns, v, a)

    def update(self, speeds: dict[int, float], t_ns: int) -> dict[int, float]:
        """This cycle's speeds over ground by track id; the filtered accelerations."""
        out: dict[int, float] = {}
        state: dict[int, tuple[int, float, float]] = {}
        for tid, v in speeds.items():
            prev = self._state.get(tid)
            a = 0.0
            if prev is not None and 0 < t_ns - prev[0] <= self.max_gap_ns:
                dt = (t_ns - prev[0]) / 1e9
                raw = max(-self.limit, min(self.limit, (v - prev[1]) / dt))
                alpha = 1.0 - math.exp(-dt / self.tau_s)
                a = prev[2] + alpha * (raw - prev[2])
            state[tid] = (t_ns, v, a)
            out[tid] = a
        self._state = state
        return out


# Stages of the kinematic rule, by severity: the brake level comes with the stage.
STAGE_WARNING = "warning"
STAGE_PARTIAL = "partial"
STAGE_FULL = "full"


class KinematicRule:
    """The kinematic rule, from the settings. Per cycle `begin` takes the vehicle's
    state and the confirmed tracks (the path, each track's acceleration); then
    `kinematics` and `threat` per track, as DecisionRule's.

    Stale or missing `vehicle/motion` (`degraded`): the paper's rule on the straight
    corridor (DecisionRule, the same settings), at most WARNING. Stale or missing
    `vehicle/driver` with fresh motion: this rule, at most WARNING (no override could be
    seen). The reason starts ``vehicle state ...: at most WARNING``."""

    def __init__(self, s: DecisionSettings) -> None:
        self.s = s
        self.k = s.kinematic
        self.paper = DecisionRule(s)
        self.policy = s.unverifiable_policy
        self.min_range = s.kinematic.range_min_m
        p = s.corridor.prediction
        self.predict = p.enabled
        self.horizon = p.horizon_s
        self.arrival_margin = p.arrival_margin_s
        self.trailing = trailing_lengths(p)
        self.centre = s.corridor.center_y_m
        self.accel = LeadAcceleration(self.k.accel_filter_s, self.k.max_accel_mps2)
        self.vehicle: VehicleSample | None = None
        self.degraded = "vehicle state not read"     # empty while motion and driver are fresh
        self.motion_ok = False
        self.ego_mps = 0.0
        self.yaw_rps = 0.0
        self.path: PredictedPath = straight_path(
            s.corridor.half_width_m + s.corridor.margin_m, s.kinematic.range_max_m,
            self.centre, "no vehicle state")
        self.max_range = s.max_range_m
        self._accels: dict[int, float] = {}
        self._ground: dict[int, tuple[float, float]] = {}   # id -> (along, across) over ground
        # This cycle's tracks in path coordinates, by (id, x, y): one point per track.
        self._points: dict[tuple[int, float, float], PathPoint] = {}
        self._edge: dict[int, str] = {}    # id -> why it is the road's edge, this cycle
        # The tracks whose radar point the path held, this cycle (as `kinematics` finds
        # them: every confirmed track is judged each cycle) and the one before.
        self._point_in: set[int] = set()
        self._point_in_before: set[int] = set()
        # The tracks standing still over ground, this cycle and the one before.
        self._still: set[int] = set()
        self._still_before: set[int] = set()
        # The yaw rate as the radar's lateral velocities follow it (low-passed with
        # turn_lag_s): None until the first motion, and again after motion was lost.
        self._yaw_lagged: tuple[float, int] | None = None     # (rad/s, stamp)
        self._yaw_step_rps = 0.0       # this cycle's yaw rate less the lagged one

    def begin(self, vehicle: VehicleSample, tracks: Sequence[RadarTrack],
              stamp_ns: int) -> None:
        """This cycle's vehicle state and confirmed (finite) tracks, at the radar cycle's
        stamp."""
        self.vehicle = vehicle
        motion = vehicle.motion
        self.motion_ok = motion is not None
        self.degraded = vehicle.reason
        self._ground = {}
        self._points = {}
        self._accels = {}
        self._edge = {}
        self._point_in_before, self._point_in = self._point_in, set()
        self._still_before, self._still = self._still, set()
        if motion is None:
            self._point_in_before = set()
            self._still_before = set()
            self._yaw_lagged = None
            self._yaw_step_rps = 0.0
            self.path = straight_path(self.s.corridor.half_width_m + self.s.corridor.margin_m,
                                      self.s.max_range_m, self.centre, "no vehicle state")
            self.accel.update({}, stamp_ns)
            return
        k = self.k
        self.ego_mps = v = motion.speed_mps
        self.yaw_rps = w = math.radians(motion.yaw_rate_dps)
        self._yaw_step_rps = w - self._lagged_yaw(w, stamp_ns)
        steer = vehicle.driver.steering_wheel_angle_deg if vehicle.driver is not None else None
        self.path = predicted_path(v, motion.yaw_rate_dps, steer, self.s.path, self.centre)
        self.max_range = min(k.range_max_m, k.range_base_m + k.range_time_s * max(v, 0.0),
                             self.s.path.length_m)
        # Over ground: the radar's velocities are relative to the turning vehicle frame.
        over = {t.track_id: (t.vx_mps + v - w * t.y_m, t.vy_mps + w * t.x_m) for t in tracks}
        turn = self._unseen_turn(tracks, over)
        if turn:
            self.path = replace(self.path, source=(
                f"{self.path.source}; the radar's stationary returns turn "
                f"{math.degrees(turn):+.1f} deg/s more"))
        max_turn = self.s.path.max_curvature_per_m * abs(v)
        self._points = {(t.track_id, t.x_m, t.y_m): self.path.point(t.x_m, t.y_m)
                        for t in tracks}
        for t in tracks:
            gx, gy = over[t.track_id]
            if turn and t.misses == 0:
                # Each radar filter follows a turn at its own pace: what stood still and
                # drifts the turn's way stands; the others take the turn's median. A
                # coasting track's velocity is the one predicted before the turn.
                own = -gy / t.x_m if t.x_m > 0.0 else 0.0
                if not (t.track_id in self._still_before and own * turn > 0.0
                        and abs(own) <= max_turn):
                    own = turn
                gx, gy = gx - own * t.y_m, gy + own * t.x_m
            p = self._points[t.track_id, t.x_m, t.y_m]
            self._ground[t.track_id] = self.path.velocity(p, gx, gy)
        still = self.s.road_edge.stationary_mps
        self._still = {i for i, g in self._ground.items() if math.hypot(*g) < still}
        self._accels = self.accel.update({i: g[0] for i, g in self._ground.items()}, stamp_ns)
        if self.s.road_edge.enabled:
            self._edge = self._road_edge()

    def _unseen_turn(self, tracks: Sequence[RadarTrack],
                     over: Mapping[int, tuple[float, float]]) -> float:
        """The ego's rotation (rad/s, left positive) beyond the vehicle state's yaw rate
        that the tracks standing still the cycle before and measured in this one show
        (`over`: their velocity over ground by that yaw rate, vehicle axes; a coasting
        track's is the one predicted before the turn); 0.0 where they show none."""
        k = self.k
        if k.unseen_turn_min_tracks == 0:
            return 0.0
        near = max(k.unseen_turn_min_range_m, 1.0)
        ratios = [-over[t.track_id][1] / t.x_m for t in tracks
                  if t.track_id in self._still_before and t.x_m >= near and t.misses == 0]
        return unseen_turn(ratios, k.unseen_turn_min_tracks, k.unseen_turn_min_rps)

    def _lagged_yaw(self, yaw_rps: float, stamp_ns: int) -> float:
        """The yaw rate low-passed with `turn_lag_s` up to `stamp_ns` (a radar cycle's),
        as the radar's filtered lateral velocities have followed it."""
        prev, tau = self._yaw_lagged, self.k.turn_lag_s
        if prev is None or tau <= 0.0:
            lagged, t = yaw_rps, stamp_ns
        else:
            dt_s = max(0, stamp_ns - prev[1]) / 1e9
            lagged = prev[0] + (yaw_rps - prev[0]) * (1.0 - math.exp(-dt_s / tau))
            t = max(stamp_ns, prev[1])
        self._yaw_lagged = (lagged, t)
        return lagged

    def _road_edge(self) -> dict[int, str]:
        """The stationary tracks that form the road's edge this cycle (road_edge.py)."""
        e = self.s.road_edge
        points = [EdgePoint(i, p.s_m, p.d_m) for (i, _, _), p in self._points.items()
                  if i in self._still]
        if len(points) < e.min_members:
            return {}
        edges = road_edges(points, self.path.half_width_m, self.path.curvature_per_m,
                           self.ego_mps, e, self.s.path.max_curvature_per_m)
        return on_edge(edges, e)

    def lateral_input(self, tracks: list[RadarTrack]) -> list[RadarTrack]:
        """The tracks whose sideways motion LateralMotion judges: across the path, over
        ground (a roadside post in a bend drifts sideways in the radar frame but stands
        still on the road), less the allowance for the radar's lag in a bend."""
        if not self.motion_ok:
            return tracks
        # In a bend a stationary object's lateral velocity in the radar frame (-w x)
        # changes as the ego nears it, and the radar's filtered velocity lags it by about
        # `turn_lag_s`: that much of w v is no evidence of motion. Where the yaw rate
        # itself has just changed (a bend's entry or exit), the radar's velocities still
        # follow the yaw rate that was: the step's -dw x is no evidence either.
        allowance = self.k.turn_lag_s * abs(self.yaw_rps * self.ego_mps)
        step = abs(self._yaw_step_rps)
        out = []
        for t in tracks:
            g = self._ground.get(t.track_id)
            if g is not None:
                slack = allowance + step * abs(t.x_m)
                across = math.copysign(max(0.0, abs(g[1]) - slack), g[1])
                t = msgspec.structs.replace(t, vy_mps=across)
            out.append(t)
        return out

    def kinematics(self, track: RadarTrack, moving: bool = False) -> Kinematics:
        if not self.motion_ok:
            return self.paper.kinematics(track, moving)
        k = self.k
        p = (self._points.get((track.track_id, track.x_m, track.y_m))
             or self.path.point(track.x_m, track.y_m))
        along, across = self._ground.get(track.track_id, (0.0, 0.0))
        a = self._accels.get(track.track_id, 0.0)
        v = self.ego_mps
        r = track.range_m
        in_range = self.min_range <= r <= self.max_range
        window: PathWindow | None = None
        in_path = self.path.contains(p)
        if in_path:
            self._point_in.add(track.track_id)
        lead, decel = along, max(0.0, -a)
        if moving and self.predict and v - along > 0.0 and p.s_m >= 0.0:
            arrival = p.s_m / (v - along)
            m = self.arrival_margin
            if arrival - m <= self.horizon:
                enter, leave = crossing_window(p.d_m, across, self.path.half_width_m,
                                               self.trailing.get(track.obj_class, 0.0))
                in_path = (enter <= arrival + m and leave >= max(0.0, arrival - m)
                           and p.s_m <= self.path.length_m)
                window = PathWindow(enter, leave, arrival)
                lead, decel = 0.0, 0.0      # it crosses: the ego must stop before its line
        edge = ""
        if in_path and window is None and track.track_id in self._edge:
            # A guard rail where the road bends: the straight path runs into it, the road
            # does not (road_edge.py).
            edge, in_path = self._edge[track.track_id], False
        gap = p.s_m - k.stop_margin_m
        ttc = time_to_collision(p.s_m, v, lead, decel)
        if window is not None:
            ttc = window.arrival_s
        need = required_decel(gap, v, lead, decel, k.latency_s) if v > 0.0 else 0.0
        # A point at the margin's edge (an object as far beside the path as the margin is
        # wide) flickers in and out with the radar's noise; a car whose point lies in the
        # margin stays there. One cycle in it warns; the full stage never waits.
        margin_first = (in_path and window is None and abs(p.d_m) > self.s.path.half_width_m
                        and track.track_id not in self._point_in_before)
        kin = Kinematics(r, track.range_rate_mps, p.d_m, ttc, ttc, in_range, in_path, window,
                         None, need, a, p, edge, margin_first=margin_first)
        return replace(kin, level_pct=self.level(kin))

    def beside_path(self, kin: Kinematics, x_m: float,
                    detail: Mapping[str, float]) -> str | None:
        """Why the camera takes a track the point test put in the path out of it, or None
        (also for a track the point test leaves out of it, for fusion to carry).

        The radar's point may lie within the path's margin while the object stands
        beside the path: the camera's depth (`detail`, the recall-first check's extent
        where it confirms, at the track's `x_m`) shows that only when every pixel at the
        range lies farther than half_width_m + camera_margin_m from the path's centre on
        one side, and the window reaches into the path (its limit on the path's side
        within half_width_m) with its columns between seeing through. Anything short of
        that - no extent, the crossing prediction's verdict, holes, the object touching
        the window's edge - leaves the point test's verdict."""
        keys = (AT_Y_MIN, AT_Y_MAX, WINDOW_Y_MIN, WINDOW_Y_MAX, THROUGH_LOW_Y, THROUGH_HIGH_Y)
        if (not self.motion_ok or kin.window is not None
                or any(key not in detail for key in keys)):
            return None
        half = self.s.path.half_width_m
        side, lo, hi = self._camera_side(x_m, detail)
        if side > 0:
            # Left of the path: its side is the window's low-y end.
            inner, edge = lo, self.path.point(x_m, detail[WINDOW_Y_MIN]).d_m
            clear = detail[THROUGH_LOW_Y] > 0.0
        elif side < 0:
            inner, edge = hi, -self.path.point(x_m, detail[WINDOW_Y_MAX]).d_m
            clear = detail[THROUGH_HIGH_Y] > 0.0
        else:
            return None
        if not clear or edge > half:
            return None
        return (f"beside the path by the camera: inner edge {inner:+.2f} m, limit "
                f"{half:.1f} + {self.s.path.camera_margin_m:.1f} m")

    def _camera_side(self, x_m: float, detail: Mapping[str, float]
                     ) -> tuple[int, float, float]:
        """Where the camera's pixels at the range lie (the keys must be in `detail`): +1
        every one farther than half_width_m + camera_margin_m left of the path's centre,
        -1 right, 0 reaching within that; with their lowest and highest offsets."""
        limit = self.s.path.half_width_m + self.s.path.camera_margin_m
        lo = self.path.point(x_m, detail[AT_Y_MIN]).d_m
        hi = self.path.point(x_m, detail[AT_Y_MAX]).d_m
        side = 1 if lo > limit and hi > limit else -1 if lo < -limit and hi < -limit else 0
        return side, lo, hi

    def camera_reaches_path(self, x_m: float, detail: Mapping[str, float]) -> bool:
        """Whether the camera's pixels at the range (`detail`, the recall-first check's
        extent where it confirms) come within half_width_m + camera_margin_m of the
        path's centre; False where there is no extent."""
        return (AT_Y_MIN in detail and AT_Y_MAX in detail
                and self._camera_side(x_m, detail)[0] == 0)

    def into_path_next(self, track_id: int, kin: Kinematics,
                       detail: Mapping[str, float]) -> float | None:
        """Where the camera looks next for the object of a track the point test leaves out
        of the path: the ground-y shift to the window beside this one on the path's side,
        when depth confirms the object (`detail`, the recall-first check's extent) and its
        pixels at the range run up to this window's edge on the path's side. None where it
        does not, and where the rule does not look: `camera_into_m` 0 or exceeded by the
        radar point's distance beyond the path's edge, a crossing prediction, a track on
        the road's edge (a guard rail ahead of a bend runs into the straight path), out of
        range or beyond INTO_MAX_RANGE_M, not closing, a path that bends."""
        into = self.s.path.camera_into_m
        p = kin.path_point
        if (not self.motion_ok or into <= 0.0 or p is None or kin.window is not None
                or track_id in self._edge or not kin.in_range
                or kin.range_m > INTO_MAX_RANGE_M or kin.ttc_s is None
                or (kin.in_path and not kin.by_camera)
                or abs(p.d_m) - self.path.half_width_m > into):
            return None
        # The windows step across the ground frame's y: the path's side only where the
        # path runs straight to the range (within INTO_BEND_M of a straight line).
        if abs(self.path.curvature_per_m) * p.s_m ** 2 / 2.0 > INTO_BEND_M:
            return None
        return _step_toward(detail, 1 if p.d_m < 0.0 else -1)

    def into_path(self, x_m: float, detail: Mapping[str, float], toward: int
                  ) -> tuple[str | None, float | None]:
        """A window beside the last toward the path (`toward`: +1 to higher ground y):
        (why the object is in the path, None) when the pixels at the range run on from its
        outer edge to inside the path's half-width; (None, the next window's shift) when
        they run across the whole window; (None, None) otherwise. Inside the path: within
        the vehicle's half-width (`half_width_m`), not the margin beyond it."""
        if _step_toward(detail, -toward) is None:
            return None, None            # not running on from the window's outer edge
        d = self.path.point(x_m, detail[AT_Y_MAX if toward > 0 else AT_Y_MIN]).d_m
        # Into the vehicle's own width, not only the margin: a surface at the margin's
        # edge is an object beside the path as often (beside_path).
        half = self.s.path.half_width_m
        if abs(d) <= half:
            return (f"its surface at the range reaches {d:+.2f} m from the path's centre, "
                    f"limit {half:g} m"), None
        return None, _step_toward(detail, toward)

    def threat(self, kin: Kinematics) -> tuple[Decision, str]:
        if not self.motion_ok:
            decision, reason = self.paper.threat(kin)
            return self._capped(decision, f"{reason} (paper's rule, straight corridor)")
        decision, reason = self._threat(kin)
        if decision is Decision.NONE or not self.degraded:
            return decision, reason
        return self._capped(decision, reason)

    def _capped(self, decision: Decision, reason: str) -> tuple[Decision, str]:
        if decision is Decision.BRAKE:
            decision = Decision.WARNING
        if decision is Decision.NONE:
            return decision, reason
        return decision, f"vehicle state {self.degraded}: at most WARNING; {reason}"

    def stage(self, kin: Kinematics) -> str | None:
        """The stage a track's figures reach (None: none)."""
        k = self.k
        need = kin.required_decel_mps2 or 0.0
        ttc = kin.ttc_s if kin.ttc_s is not None else math.inf
        if need >= k.full_decel_mps2 or ttc < k.full_ttc_s:
            return STAGE_FULL
        if need >= k.partial_decel_mps2 or ttc < k.partial_ttc_s:
            return STAGE_WARNING if kin.margin_first else STAGE_PARTIAL
        if need >= k.warning_decel_mps2 or ttc < k.warning_ttc_s:
            return STAGE_WARNING
        return None

    def _threat(self, kin: Kinematics) -> tuple[Decision, str]:
        k = self.k
        if not kin.in_range:
            return Decision.NONE, (f"range {kin.range_m:.2f} m outside "
                                   f"[{self.min_range:g}, {self.max_range:.1f}] m")
        if self.ego_mps < k.min_speed_mps:
            return Decision.NONE, (f"ego speed {self.ego_mps:.2f} m/s below "
                                   f"{k.min_speed_mps:g} m/s")
        p = kin.path_point
        w = kin.window
        if not kin.in_path:
            if kin.road_edge:
                where = "" if p is None else f"s {p.s_m:.1f} m, offset {p.d_m:+.2f} m: "
                return Decision.NONE, (f"out of path as the road's edge ({where}"
                                       f"{kin.road_edge}, {self.path.describe()})")
            why = "" if w is None else f"; {_window_text(w)}"
            where = "" if p is None else f"s {p.s_m:.1f} m, offset {p.d_m:+.2f} m, "
            return Decision.NONE, (f"out of path ({where}limit {self.path.half_width_m:g} m,"
                                   f" {self.path.describe()}{why})")
        if kin.ttc_s is None and not kin.required_decel_mps2:
            return Decision.NONE, f"not closing (range rate {kin.range_rate_mps:+.2f} m/s)"
        stage = self.stage(kin)
        figures = (f"needs {_decel(kin.required_decel_mps2)}, TTC "
                   f"{_t(kin.ttc_s if kin.ttc_s is not None else math.inf)} s, target accel "
                   f"{kin.accel_mps2 or 0.0:+.1f} m/s^2, {self.path.describe()}")
        if w is not None:
            figures = f"in path by prediction ({_window_text(w)}), {figures}"
        elif kin.by_camera:
            figures = f"in path by the camera ({kin.by_camera}), {figures}"
        if stage is None:
            return Decision.NONE, f"no stage reached: {figures}"
        if stage == STAGE_WARNING:
            if kin.margin_first and self.stage(replace(kin, margin_first=False)) != stage:
                figures = (f"its radar point entered the path's margin this cycle, partial "
                           f"braking from the next: {figures}")
            return Decision.WARNING, f"warning: {figures}"
        return Decision.BRAKE, f"{stage} brake: {figures}"

    @property
    def cannot_tell_full_only(self) -> bool:
        return self.k.cannot_tell_full_only

    @property
    def not_visible_full_only(self) -> bool:
        return self.k.not_visible_full_only

    def cannot_tell(self, kin: Kinematics, threat: Decision, reason: str,
                    what: str = "camera cannot tell") -> tuple[Decision, str]:
        """A threat the camera cannot tell yet (`cannot_tell_full_only`): WARNING up to
        the full stage with its deceleration bound raised to `cannot_tell_decel_mps2`,
        BRAKE (at the full stage's level) from it. A radar false target at speed is
        decided where depth is too sparse to see anything; braking for it only when the
        stop really needs it keeps the partial brake for what the camera confirms."""
        if threat is Decision.NONE:
            return threat, reason
        k = self.k
        need = kin.required_decel_mps2 or 0.0
        ttc = kin.ttc_s if kin.ttc_s is not None else math.inf
        bounds = f"{k.cannot_tell_decel_mps2:g} m/s^2 or TTC {k.full_ttc_s:g} s"
        if threat is Decision.BRAKE and (need >= k.cannot_tell_decel_mps2
                                         or ttc < k.full_ttc_s):
            return Decision.BRAKE, f"{what}, full stage ({bounds}): {reason}"
        return Decision.WARNING, f"{what}, warning until the full stage ({bounds}): {reason}"

    def level(self, kin: Kinematics) -> float | None:
        """The brake level of a track's stage (None below the partial stage)."""
        if not self.motion_ok:
            return None
        stage = self.stage(kin)
        return (self.k.full_level_pct if stage == STAGE_FULL else
                self.k.partial_level_pct if stage == STAGE_PARTIAL else None)


# How close to a window's edge the pixels at the range count as running up to it: a
# pixel 25 m ahead spans 6 cm.
INTO_TOUCH_M = 0.1
# The most the path may bend away from a straight line to a track's range for the camera
# to follow its object sideways.
INTO_BEND_M = 0.2
# Beyond this range the check's depth tolerance (over 5 m at 25 m) takes a guard rail or
# a row of parked cars seen at a slant for one surface at the range.
INTO_MAX_RANGE_M = 25.0
_EXTENT = (AT_Y_MIN, AT_Y_MAX, WINDOW_Y_MIN, WINDOW_Y_MAX)


def _step_toward(detail: Mapping[str, float], toward: int) -> float | None:
    """The shift (ground y) to the window beside this one on the `toward` side, when the
    pixels at the range reach this window's edge there; else None."""
    if any(key not in detail for key in _EXTENT):
        return None
    lo, hi = detail[WINDOW_Y_MIN], detail[WINDOW_Y_MAX]
    if toward > 0 and detail[AT_Y_MAX] >= hi - INTO_TOUCH_M:
        return hi - lo
    if toward < 0 and detail[AT_Y_MIN] <= lo + INTO_TOUCH_M:
        return lo - hi
    return None


def _decel(d: float | None) -> str:
    if d is None:
        return "-"
    return f"{d:.2f} m/s^2" if math.isfinite(d) else "inf m/s^2 (gap gone within the latency)"


OVERRIDE_KICKDOWN = "kick-down"
OVERRIDE_STEERING = "steering"
OVERRIDE_BRAKE_PEDAL = "brake pedal"


@dataclass(frozen=True, slots=True)
class StagedCommand:
    """The command after the hold, the standstill hold and the driver's override.
    `note`: what they did, for the reason (empty: nothing); `override`: the driver's
    override in force (empty: none)."""

    decision: Decision
    level_pct: float
    held: bool
    note: str = ""
    override: str = ""


class CommandStage:
    """From the most severe target decision of a cycle to the command.

    The paper's rule (`rule` None): the brake hold, at `brake_level_pct`. The kinematic
    rule: the driver's override first (a kick-down or a steering manoeuvre suppresses
    AEB while it lasts and `suppress_s` after, the brake pedal releases AEB to the
    driver while pressed: at most WARNING, any hold ended); then a brake that brought the
    ego to a stop holds it at `standstill_level_pct` for `standstill_hold_s` and releases
    (no new activation until it moves again); then the hold. Within one brake the level
    never drops (partial to full, not back: no chatter between stages)."""

    def __init__(self, s: DecisionSettings, hold: BrakeHold,
                 rule: KinematicRule | None) -> None:
        self.s = s
        self.hold = hold
        self.rule = rule
        self._level = 0.0                         # the brake's level so far
        self._standstill_until: int | None = None
        self._released = False                    # the standstill hold ended, ego still
        self._suppress_until: int | None = None
        self._suppress_why = ""

    def update(self, decision: Decision, level_pct: float | None, track_id: int,
               now_ns: int) -> StagedCommand:
        rule = self.rule
        if rule is None:
            held = self.hold.update(decision, track_id, now_ns)
            brake = decision is Decision.BRAKE or held
            return StagedCommand(Decision.BRAKE if held else decision,
                                 self.s.brake_level_pct if brake else 0.0, held)
        override = self._override(now_ns)
        if override:
            braking = self._level > 0.0 or self.hold.until_ns is not None
            self._end_brake()
            capped = Decision.WARNING if decision is Decision.BRAKE else decision
            what = ("AEB released to the driver" if override == OVERRIDE_BRAKE_PEDAL
                    else "AEB suppressed")
            cancelled = ", brake cancelled" if braking else ""
            note = (f"driver override ({override}): {what}{cancelled}"
                    if braking or decision is not Decision.NONE else "")
            return StagedCommand(capped, 0.0, False, note, override)
        k = self.s.kinematic
        stopped = rule.motion_ok and rule.ego_mps <= k.standstill_mps
        if not stopped:
            self._released = False
        if self._standstill_until is not None:
            if now_ns < self._standstill_until:
                left = (self._standstill_until - now_ns) / 1e6
                return StagedCommand(Decision.BRAKE, k.standstill_level_pct, True,
                                     f"standstill hold {left:.0f} ms more")
            self._end_brake()
            self._released = True
        if self._released:
            capped = Decision.WARNING if decision is Decision.BRAKE else decision
            return StagedCommand(capped, 0.0, False,
                                 "standstill hold over: released" if capped is not decision
                                 else "")
        held = self.hold.update(decision, track_id, now_ns)
        if decision is not Decision.BRAKE and not held:
            self._level = 0.0
            return StagedCommand(decision, 0.0, False)
        self._level = max(self._level, level_pct or 0.0, k.partial_level_pct)
        if stopped:
            self._standstill_until = now_ns + round(k.standstill_hold_s * 1e9)
            return StagedCommand(Decision.BRAKE, k.standstill_level_pct, True,
                                 "ego stopped: standstill hold")
        return StagedCommand(Decision.BRAKE, self._level, held)

    def _end_brake(self) -> None:
        self.hold.clear()
        self._level = 0.0
        self._standstill_until = None

    def _override(self, now_ns: int) -> str:
        """The driver's override in force now ("" none)."""
        o = self.s.override
        rule = self.rule
        vehicle = rule.vehicle if rule is not None else None
        d = vehicle.driver if vehicle is not None else None
        if not o.enabled or d is None:
            return ""
        why = ""
        if d.kickdown or (o.accelerator_pct is not None and d.accelerator_pedal_pct is not None
                          and d.accelerator_pedal_pct >= o.accelerator_pct):
            why = OVERRIDE_KICKDOWN
        elif ((o.steering_rate_dps is not None and d.steering_wheel_rate_dps is not None
               and abs(d.steering_wheel_rate_dps) >= o.steering_rate_dps)
              or (o.steering_angle_deg is not None and d.steering_wheel_angle_deg is not None
                  and abs(d.steering_wheel_angle_deg) >= o.steering_angle_deg)):
            why = OVERRIDE_STEERING
        if why:
            self._suppress_until = now_ns + round(o.suppress_s * 1e9)
            self._suppress_why = why
        if o.brake_pedal and d.brake_pedal_pressed:
            return OVERRIDE_BRAKE_PEDAL
        if self._suppress_until is not None and now_ns <= self._suppress_until:
            return self._suppress_why
        self._suppress_until = None
        return ""
