"""The road's lane centre line and the frames the simulator works in, pure.

A SIMULATION's geometry. World frame: x forward along the road's first straight, y left,
origin on the ground below the ego's radar at t = 0. Road coordinates: station `s` along
the ego lane's centre line (from the origin) and lateral offset `d` (left positive) from
it. The centre line is straight up to `curve_start_m`, then an arc of constant signed
radius (positive: a left bend) that continues from there. On a straight road the road
coordinates are the world frame.

The vehicle frame is the ego's (and its radar's): x forward along the ego's heading, y
left, origin at the radar on the ego's front. A `Pose` is where that frame is in the
world.
"""

import math
from dataclasses import dataclass

import numpy as np

from aeb_radar_camera.tools.messages import RoadGeometry


@dataclass(frozen=True)
class Pose:
    """A frame in the world: origin (x, y) and heading (radians, left positive)."""

    x_m: float = 0.0
    y_m: float = 0.0
    heading_rad: float = 0.0

    def to_local(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) world points in this frame."""
        c, s = math.cos(self.heading_rad), math.sin(self.heading_rad)
        d = np.asarray(xy, np.float64) - (self.x_m, self.y_m)
        return np.column_stack([d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c])

    def to_world(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) points of this frame in the world."""
        c, s = math.cos(self.heading_rad), math.sin(self.heading_rad)
        p = np.asarray(xy, np.float64)
        return np.column_stack([self.x_m + p[:, 0] * c - p[:, 1] * s,
                                self.y_m + p[:, 0] * s + p[:, 1] * c])

    def point_to_local(self, x: float, y: float) -> tuple[float, float]:
        """One world point in this frame."""
        c, s = math.cos(self.heading_rad), math.sin(self.heading_rad)
        dx, dy = x - self.x_m, y - self.y_m
        return dx * c + dy * s, -dx * s + dy * c

    def rotate_to_local(self, vx: float, vy: float) -> tuple[float, float]:
        """A world vector (a velocity) in this frame's axes."""
        c, s = math.cos(self.heading_rad), math.sin(self.heading_rad)
        return vx * c + vy * s, -vx * s + vy * c


class Road:
    """The lane centre line of a `RoadGeometry`: conversions between road coordinates
    (station, lateral offset) and the world frame."""

    def __init__(self, geometry: RoadGeometry | None = None) -> None:
        self.geometry = geometry or RoadGeometry()
        self.s0 = self.geometry.curve_start_m
        r = self.geometry.radius_m
        self.radius = r                          # signed; None: straight
        self.k = 0.0 if r is None else 1.0 / r   # curvature, 1/m, left positive

    @property
    def straight(self) -> bool:
        return self.k == 0.0

    def curvature_at(self, s: float) -> float:
        """Curvature (1/m, left positive) of the centre line at station `s`."""
        return self.k if s > self.s0 else 0.0

    def heading_at(self, s: float) -> float:
        """The centre line's heading at station `s` (radians, left positive)."""
        return self.k * (s - self.s0) if s > self.s0 else 0.0

    def pose_at(self, s: float, d: float = 0.0) -> Pose:
        """The world pose of the point (s, d), heading along the centre line's tangent."""
        return Pose(*self.point(s, d), self.heading_at(s))

    def point(self, s: float, d: float = 0.0) -> tuple[float, float]:
        """The world point of one (s, d): `to_world` without arrays (per object, per step)."""
        if self.straight or s <= self.s0:
            return s, d
        r = self.radius
        assert r is not None
        theta = self.k * (s - self.s0)
        return self.s0 + (r - d) * math.sin(theta), r - (r - d) * math.cos(theta)

    def to_world(self, s: np.ndarray, d: np.ndarray) -> np.ndarray:
        """(N, 2) world points of road coordinates (arrays of N)."""
        s = np.asarray(s, np.float64)
        d = np.asarray(d, np.float64)
        if self.straight:
            return np.column_stack([s, d])
        theta = self.k * np.maximum(s - self.s0, 0.0)
        r = self.radius
        assert r is not None
        on_arc = s > self.s0
        x = np.where(on_arc, self.s0 + (r - d) * np.sin(theta), s)
        y = np.where(on_arc, r - (r - d) * np.cos(theta), d)
        return np.column_stack([x, y])

    def to_road(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Road coordinates (s, d) of world points (arrays of any shape, float32 or
        float64: the renderer maps every ground pixel through this). Points beside the
        arc are placed on the arc from its start on (up to half a turn ahead), before it
        on the straight."""
        if self.straight:
            return x, y
        r = self.radius
        assert r is not None
        sign = 1.0 if r > 0 else -1.0
        s, d = x.copy(), y.copy()
        on_arc = x > self.s0
        if on_arc.any():
            dx, ry = x[on_arc] - self.s0, r - y[on_arc]
            theta = np.arctan2(sign * dx, sign * ry)      # 0 at the arc's start, sign of r
            s[on_arc] = self.s0 + r * theta
            d[on_arc] = r - sign * np.hypot(dx, ry)
        return s, d

    def heading_of(self, s: np.ndarray) -> np.ndarray:
        """The tangent's heading at stations `s` (array)."""
        return self.k * np.maximum(np.asarray(s, np.float64) - self.s0, 0.0)


@dataclass(frozen=True)
class RoadView:
    """Where the ego is on a road: its radar's station and lateral offset (its heading
    is the road's there)."""

    road: Road
    s_m: float
    d_m: float = 0.0

    @property
    def pose(self) -> Pose:
        return self.road.pose_at(self.s_m, self.d_m)
