"""The ego's predicted path for the kinematic rule (pure, no I/O, no clocks).

An arc from the radar (the vehicle frame's origin, x forward, y left), tangent to x at
`center_y_m`, of curvature yaw rate / speed (left positive). Below a minimum speed the
yaw rate is mostly noise (a rate gyro's bias over a speed near 0), so the curvature
comes from the steering wheel through a bicycle model (road wheel angle = wheel angle /
steering ratio, curvature = tan(angle) / wheelbase) when the wheelbase is configured,
else the path is straight. A point is placed on the path by its arc length `s` (of its
foot on the arc, from the radar) and its signed offset `d` from the arc (left positive);
it is in the path iff 0 <= s <= length and |d| <= half width + margin.

The arc is the radar's, not the rear axle's: the front of a turning car runs a little
outside the rear axle's circle (about wheelbase^2 / 2R: 7 cm at R = 50 m for 2.7 m),
inside the margin.
"""

import math
from dataclasses import dataclass

from aeb_radar_camera.common.config.fusion import PathSettings

# Below this |curvature| (1/m, a 10 km radius) the arc is computed as a straight line:
# the circle's centre would be too far away for the arithmetic.
STRAIGHT_CURVATURE = 1e-4


@dataclass(frozen=True, slots=True)
class PathPoint:
    """A point in path coordinates: arc length along the path, signed offset from it."""

    s_m: float
    d_m: float


@dataclass(frozen=True, slots=True)
class PredictedPath:
    """The arc and its corridor. `source`: where the curvature came from (``yaw rate``,
    ``steering``, ``straight``: no usable yaw rate and no steering model)."""

    curvature_per_m: float
    half_width_m: float          # including the margin
    length_m: float
    center_y_m: float = 0.0
    source: str = "straight"

    def point(self, x_m: float, y_m: float) -> PathPoint:
        """(x, y) in the vehicle frame as arc length and offset. Points behind the radar
        get a negative arc length."""
        k = self.curvature_per_m
        y = y_m - self.center_y_m
        if abs(k) < STRAIGHT_CURVATURE:
            return PathPoint(x_m, y)
        r = 1.0 / k                     # signed radius: the centre is at (0, r)
        vx, vy = x_m, y - r
        rho = math.hypot(vx, vy)
        sign = 1.0 if k > 0 else -1.0
        theta = math.atan2(vx, -sign * vy)   # swept from the radar, forward positive
        return PathPoint(theta * abs(r), sign * (abs(r) - rho))

    def at(self, s_m: float, d_m: float) -> tuple[float, float]:
        """The vehicle-frame (x, y) of arc length `s_m` and offset `d_m`: the inverse of
        `point`."""
        k = self.curvature_per_m
        if abs(k) < STRAIGHT_CURVATURE:
            return s_m, d_m + self.center_y_m
        r = 1.0 / k
        theta = s_m * k
        return (r - d_m) * math.sin(theta), r - (r - d_m) * math.cos(theta) + self.center_y_m

    def velocity(self, p: PathPoint, vx_mps: float, vy_mps: float) -> tuple[float, float]:
        """A velocity (vehicle axes) at the path point `p` along the path's tangent and
        normal there (left positive)."""
        k = self.curvature_per_m
        if abs(k) < STRAIGHT_CURVATURE:
            return vx_mps, vy_mps
        heading = p.s_m * k             # the tangent's direction at the foot point
        c, s = math.cos(heading), math.sin(heading)
        return vx_mps * c + vy_mps * s, -vx_mps * s + vy_mps * c

    def contains(self, p: PathPoint) -> bool:
        return 0.0 <= p.s_m <= self.length_m and abs(p.d_m) <= self.half_width_m

    def describe(self) -> str:
        k = self.curvature_per_m
        if abs(k) < STRAIGHT_CURVATURE:
            return f"straight path ({self.source})"
        side = "left" if k > 0 else "right"
        return f"path R {1 / abs(k):.0f} m {side} ({self.source})"


def curvature(speed_mps: float, yaw_rate_dps: float, steering_wheel_deg: float | None,
              s: PathSettings) -> tuple[float, str]:
    """The path's curvature (1/m, left positive) and its source. `steering_wheel_deg`:
    None when the car does not provide it."""
    if abs(speed_mps) >= max(s.min_yaw_speed_mps, 1e-3):
        k, source = math.radians(yaw_rate_dps) / abs(speed_mps), "yaw rate"
    elif s.wheelbase_m is not None and steering_wheel_deg is not None:
        wheel = math.radians(steering_wheel_deg) / s.steering_ratio
        k, source = math.tan(wheel) / s.wheelbase_m, "steering"
    else:
        return 0.0, "straight"
    lim = s.max_curvature_per_m
    return max(-lim, min(lim, k)), source


def predicted_path(speed_mps: float, yaw_rate_dps: float, steering_wheel_deg: float | None,
                   s: PathSettings, center_y_m: float = 0.0) -> PredictedPath:
    """The path from the ego's motion and the settings."""
    k, source = curvature(speed_mps, yaw_rate_dps, steering_wheel_deg, s)
    return PredictedPath(k, s.half_width_m + s.margin_m, s.length_m, center_y_m, source)


def straight_path(half_width_m: float, length_m: float, center_y_m: float = 0.0,
                  source: str = "straight") -> PredictedPath:
    return PredictedPath(0.0, half_width_m, length_m, center_y_m, source)
