"""The scenario generator: parametric families of test cases, each case a plain Scenario.

A SIMULATION's test cases. A family is a kind of situation with Euro NCAP's name where the
AEB protocols have one (CCRs, CCRm, CCRb, CPNA-25/75, CPFA-50, CPNC-50, CPLA-25/50,
CBNA-50, CBLA-25/50), or a descriptive one (the no-threat situations, the radar's false
targets, the generic obstacles the camera check is judged on). It has a grid: ego speeds
(10-60 km/h in 10 km/h steps where the protocol has them) times its own parameter points
(an overlap, a gap and deceleration, a bend's radius, ...). A case is (family, speed,
parameter point, seed): seed 0 is the nominal case of its grid point, any other seed a
randomised variant around it (pose, offset, size, lighting, camera and radar noise),
the same for the same (family, speed, parameters, seed) on every machine.

Seeds come in named splits (`SPLITS`): `train` for fitting anything (weights,
thresholds), `heldout` for every figure; the nominal grid (seed 0) and the demo's
scenario files belong to neither, so no figure is ever made on what was fitted on.

Timing follows Euro NCAP's impact points: a crossing target reaches the point 25 / 50 /
75 % across the ego's front (from the side it comes from) when the ego, driving on
unbraked, gets there; a target ahead is placed so that the ego reaches it. Every threat
case therefore collides without braking and no no-threat case does (tests/sim).

    python -m aeb_radar_camera.tools.sim.families --list
    python -m aeb_radar_camera.tools.sim.families --family CCRs --speed 30 --param offset=-25 --show
    python -m aeb_radar_camera.tools.sim.families --family CPNA-25 --seeds heldout:5 \
        --write out/cases
"""

import argparse
import hashlib
import json
import math
import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import msgspec
import numpy as np

from aeb_radar_camera.tools.messages import Lighting, ObjectKind
from aeb_radar_camera.tools.sim.scenario import (
    DEFAULT_SIZE,
    CameraLook,
    DriverSpec,
    EgoSpec,
    Motion,
    RadarLook,
    RoadSpec,
    Scenario,
    ScenarioKind,
    SceneObject,
    scenario_toml,
    write_scenario,
)

# Seed splits: fit on `train`, report on `heldout`; seed 0 is the nominal grid.
SPLITS: dict[str, range] = {
    "nominal": range(0, 1),
    "train": range(1000, 2000),
    "heldout": range(2000, 10000),
}

EGO_WIDTH_M = EgoSpec(speed_kph=10).width_m
LANE_WIDTH_M = 3.5
KPH = 1 / 3.6
ALL_SPEEDS = (10.0, 20.0, 30.0, 40.0, 50.0, 60.0)
# Euro NCAP's target speeds: adults walking 5 km/h (8 km/h from the far side), a child
# running 5 km/h, cyclists 15 km/h, the slower lead car of CCRm 20 km/h.
WALK_MPS = 5 * KPH
FAR_WALK_MPS = 8 * KPH
CYCLE_MPS = 15 * KPH
CCRM_LEAD_MPS = 20 * KPH
CHILD_SIZE = (0.3, 0.45, 1.15)
# Where crossing targets start: the kerb of the ego's side (near) or of the far lane.
NEAR_START_M = 4.5
FAR_START_M = 6.0
# Euro NCAP's steady-state distance D of CBNA: the cyclist is at its 15 km/h over the last
# 17 m before the impact point (AEB VRU test protocol).
CBNA_STEADY_M = 17.0
LOOKAHEAD_S = 4.0        # a target comes into reach this long before impact, at least
MAX_LATERAL_MPS2 = 5.0   # bend cases only at speeds a driver takes the bend at

ParamValue = float | str
Params = tuple[tuple[str, ParamValue], ...]


def split_of(seed: int) -> str:
    """The split a seed belongs to. Raises ValueError for a seed in none."""
    for name, seeds in SPLITS.items():
        if seed in seeds:
            return name
    raise ValueError(f"seed {seed} is in no split ({describe_splits()})")


def describe_splits() -> str:
    return ", ".join(f"{n} {r.start}-{r.stop - 1}" for n, r in SPLITS.items())


def seeds_of(spec: str) -> list[int]:
    """Seeds from a command-line spec: `nominal`, `train:N` / `heldout:N` (the split's
    first N), `A-B`, or a comma list of numbers. Raises ValueError."""
    spec = spec.strip()
    if spec in SPLITS:
        return list(SPLITS[spec])[:1] if spec == "nominal" else list(SPLITS[spec])
    if ":" in spec:
        name, n = spec.split(":", 1)
        if name not in SPLITS:
            raise ValueError(f"no split {name!r} ({describe_splits()})")
        return list(SPLITS[name][:int(n)])
    if "-" in spec.lstrip("-"):
        a, b = spec.split("-", 1)
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in spec.split(",") if s.strip()]


@dataclass(frozen=True)
class Case:
    """One test case: a family's grid point (ego speed, parameters) and a seed."""

    family: str
    speed_kph: float
    params: Params = ()
    seed: int = 0

    @property
    def name(self) -> str:
        label = "".join(f"_{k}{_fmt(v)}" for k, v in self.params)
        return f"{self.family}_{self.speed_kph:g}kph{label}_s{self.seed}"

    def param(self, key: str) -> ParamValue:
        return dict(self.params)[key]

    def scenario(self) -> Scenario:
        """The case as a Scenario. Raises KeyError for an unknown family."""
        return FAMILIES[self.family].build(self)


def _fmt(v: ParamValue) -> str:
    return v if isinstance(v, str) else f"{v:g}"


class Draw:
    """The randomness of one case: every draw gives the nominal value at seed 0, else a
    value from a generator seeded by a hash of the case (stable across machines and
    Python runs, unlike hash())."""

    def __init__(self, case: Case) -> None:
        self.nominal = case.seed == 0
        key = json.dumps([case.family, case.speed_kph, list(case.params), case.seed])
        digest = hashlib.sha256(key.encode()).digest()
        self.rng = np.random.default_rng(int.from_bytes(digest[:8], "little"))
        self.scene_seed = int.from_bytes(digest[8:12], "little") % 1_000_000

    def uniform(self, nominal: float, lo: float, hi: float) -> float:
        return nominal if self.nominal else float(self.rng.uniform(lo, hi))

    def jitter(self, nominal: float, half_range: float) -> float:
        return self.uniform(nominal, nominal - half_range, nominal + half_range)

    def choice(self, nominal: str, options: Sequence[str]) -> str:
        return nominal if self.nominal else str(options[int(self.rng.integers(len(options)))])


@dataclass(frozen=True)
class Family:
    """A parametric family: its grid and how a case of it becomes a Scenario."""

    name: str
    kind: ScenarioKind
    group: str                   # euro_ncap | bend | road_edge | no_threat | false_target |
    #                              obstacle | override
    description: str
    speeds_kph: tuple[float, ...]
    points: tuple[Params, ...]
    make: Callable[["Build"], None]
    lightings: tuple[str, ...] = ("day", "dusk")      # what variants draw from
    allowed: Callable[[float, Params], bool] = field(default=lambda v, p: True)

    def grid(self) -> list[tuple[float, Params]]:
        return [(v, p) for v in self.speeds_kph for p in self.points if self.allowed(v, p)]

    def cases(self, seeds: Sequence[int] = (0,)) -> list[Case]:
        return [Case(self.name, v, p, s) for v, p in self.grid() for s in seeds]

    def build(self, case: Case) -> Scenario:
        b = Build(self, case)
        self.make(b)
        return b.scenario()


class Build:
    """What a family's maker fills in for one case; `scenario()` assembles it."""

    def __init__(self, family: Family, case: Case) -> None:
        self.family = family
        self.case = case
        self.draw = Draw(case)
        self.v = case.speed_kph * KPH
        self.objects: list[SceneObject] = []
        self.road = RoadSpec()
        self.driver = DriverSpec()
        self.duration_s = 10.0
        light = case.params and dict(case.params).get("light")
        self.lighting = Lighting(str(light)) if light else Lighting(
            self.draw.choice("day", family.lightings))
        self.description = family.description

    def p(self, key: str) -> ParamValue:
        return self.case.param(key)

    def pf(self, key: str) -> float:
        return float(self.case.param(key))

    def add(self, kind: ObjectKind, s: float, d: float, yaw_deg: float = 0.0,
            size: tuple[float, float, float] | None = None, motion: Motion | None = None,
            name: str = "", z_m: float | None = None) -> None:
        self.objects.append(SceneObject(kind, round(s, 3), round(d, 3), round(yaw_deg, 2),
                                        size, motion, name, z_m))

    def until(self, station_m: float, closing_mps: float | None = None,
              after_s: float = 3.0) -> None:
        """Long enough for the ego to reach `station_m` closing at `closing_mps` (its own
        speed when None), and `after_s` more."""
        closing = self.v if closing_mps is None else closing_mps
        self.duration_s = max(self.duration_s, station_m / max(closing, 0.5) + after_s)

    def scaled(self, kind: ObjectKind, spread: float = 0.1) -> tuple[float, float, float]:
        """The kind's size, scaled by a draw around 1 (variants)."""
        k = self.draw.uniform(1.0, 1 - spread, 1 + spread)
        length, width, height = DEFAULT_SIZE[kind]
        return (round(length * k, 3), round(width * k, 3), round(height * k, 3))

    def approach(self, closing_mps: float | None = None, minimum_m: float = 30.0) -> float:
        """A start gap that gives the stack LOOKAHEAD_S of sight before impact (a draw
        of up to 10 m more in variants)."""
        closing = self.v if closing_mps is None else closing_mps
        return max(minimum_m, closing * LOOKAHEAD_S + 10.0) + self.draw.uniform(0.0, 0.0, 10.0)

    def scenario(self) -> Scenario:
        d = self.draw
        radar = RadarLook()
        camera = CameraLook()
        if not d.nominal:
            k = d.uniform(1.0, 0.8, 1.3)
            radar = msgspec.structs.replace(
                radar, range_sigma_m=round(radar.range_sigma_m * k, 3),
                lateral_sigma_m=round(radar.lateral_sigma_m * k, 3),
                velocity_sigma_mps=round(radar.velocity_sigma_mps * k, 3))
            camera = CameraLook(noise=round(d.uniform(2.0, 1.0, 4.0), 2))
        c = self.case
        return Scenario(
            name=c.name, kind=self.family.kind, ego=EgoSpec(speed_kph=c.speed_kph),
            object=tuple(self.objects), description=self.description,
            duration_s=round(min(self.duration_s, 120.0), 1), seed=d.scene_seed,
            lighting=self.lighting, road=self.road, radar=radar, camera=camera,
            driver=self.driver)


# -- the makers ------------------------------------------------------------------------------

def _offset_m(b: Build) -> float:
    """A target's lateral offset from the ego's centre line: Euro NCAP's overlap as an
    offset in % of the ego's width (0: full overlap, +-50: half of it, left / right)."""
    return b.pf("offset") / 100.0 * EGO_WIDTH_M + b.draw.jitter(0.0, 0.05)


def _impact_d(pct: float, from_right: bool) -> float:
    """The lateral position of the point `pct` % across the ego's front from the side a
    crossing target comes from."""
    edge = -EGO_WIDTH_M / 2 if from_right else EGO_WIDTH_M / 2
    return edge + (1 if from_right else -1) * pct / 100.0 * EGO_WIDTH_M


def _crossing(b: Build, kind: ObjectKind, speed_mps: float, pct: float, from_right: bool,
              start_m: float, size: tuple[float, float, float] | None = None,
              name: str = "target") -> float:
    """A target crossing the ego's path, timed to be hit at `pct` % of its front; returns
    its station (its path)."""
    d = b.draw
    size = size or b.scaled(kind)
    speed = d.jitter(speed_mps, 0.1 * speed_mps)
    pct = d.jitter(pct, 5.0)
    sign = 1.0 if from_right else -1.0
    d0 = -sign * d.jitter(start_m, 0.5)
    d_hit = _impact_d(pct, from_right)
    walk_s = abs(d_hit - d0) / speed
    station = b.approach(minimum_m=b.v * (walk_s + 1.5) + 10.0)
    depth = size[1] / 2               # across the road the body is as wide as it is
    # The ego's front reaches the target's near face when it has walked to d_hit.
    hit_t = (station - depth) / b.v
    trigger = station - b.v * (hit_t - walk_s)
    yaw = 90.0 * sign
    b.add(kind, station, d0, d.jitter(yaw, 5.0), size,
          Motion(speed_mps=round(speed, 3), heading_deg=yaw, trigger_gap_m=round(trigger, 3),
                 distance_m=round(abs(d0) + start_m, 3)), name)
    b.until(station)
    return station


def _ccr_stationary(b: Build) -> None:
    gap = b.approach()
    car = b.scaled(ObjectKind.CAR, 0.05)
    b.add(ObjectKind.CAR, gap + car[0] / 2, _offset_m(b), b.draw.jitter(0.0, 2.0), car,
          name="stopped car")
    b.until(gap)


def _ccr_moving(b: Build) -> None:
    closing = b.v - CCRM_LEAD_MPS
    gap = b.approach(closing, 20.0)
    car = b.scaled(ObjectKind.CAR, 0.05)
    b.add(ObjectKind.CAR, gap + car[0] / 2, _offset_m(b), 0.0, car,
          Motion(speed_mps=CCRM_LEAD_MPS), "slower lead car")
    b.until(gap, closing)


def _ccr_braking(b: Build) -> None:
    """Both at the ego's speed `gap_m` apart; the lead brakes at `decel_mps2` to a stop
    after two seconds of steady driving."""
    gap = b.pf("gap_m") + b.draw.jitter(0.0, 0.5)
    decel = b.pf("decel_mps2")
    car = b.scaled(ObjectKind.CAR, 0.05)
    brake_after = round(b.draw.uniform(2.0, 1.5, 3.0), 2)
    b.add(ObjectKind.CAR, gap + car[0] / 2, b.draw.jitter(0.0, 0.1), 0.0, car,
          Motion(speed_mps=b.v, brake_after_s=brake_after, decel_mps2=decel),
          "braking lead car")
    stop_s = b.v / decel
    b.duration_s = brake_after + stop_s + (gap + b.v * stop_s / 2) / b.v + 3.0


def _pedestrian_crossing(pct: float, from_right: bool, speed_mps: float, start_m: float
                         ) -> Callable[[Build], None]:
    def make(b: Build) -> None:
        _crossing(b, ObjectKind.PEDESTRIAN, speed_mps, pct, from_right, start_m)
    return make


def _child_behind_cars(b: Build) -> None:
    """A child runs out from in front of two cars parked on the ego's side, hidden from
    radar and camera until it clears the nearer car's inner side."""
    d = b.draw
    car_d = -(EGO_WIDTH_M / 2 + 1.0 + DEFAULT_SIZE[ObjectKind.CAR][1] / 2)
    size = tuple(round(x * d.uniform(1.0, 0.9, 1.1), 3) for x in CHILD_SIZE)
    station = _crossing(b, ObjectKind.PEDESTRIAN, WALK_MPS, 50.0, True, -car_d,
                        size=(size[0], size[1], size[2]), name="child")
    length = DEFAULT_SIZE[ObjectKind.CAR][0]
    front = station - 0.5 - d.uniform(0.0, 0.0, 0.3)
    b.add(ObjectKind.CAR, front - length / 2, car_d, 0.0, name="parked car")
    b.add(ObjectKind.CAR, front - length * 1.5 - 1.0, car_d, 0.0, name="parked car")


def _longitudinal(kind: ObjectKind, speed_mps: float) -> Callable[[Build], None]:
    def make(b: Build) -> None:
        speed = round(b.draw.jitter(speed_mps, 0.1 * speed_mps), 3)
        closing = b.v - speed
        gap = b.approach(closing, 20.0)
        size = b.scaled(kind)
        b.add(kind, gap + size[0] / 2, _impact_d(b.pf("impact"), True) + b.draw.jitter(0.0, 0.05),
              0.0, size, Motion(speed_mps=speed), "target ahead")
        b.until(gap, closing)
    return make


def _bicycle_crossing(b: Build) -> None:
    """Euro NCAP's CBNA: the cyclist rides its last `CBNA_STEADY_M` to the impact point
    at a steady 15 km/h (movers step to their speed, so it starts there at speed)."""
    _crossing(b, ObjectKind.BICYCLE, CYCLE_MPS, 50.0, True, CBNA_STEADY_M)


def _cyclist_from_kerb(b: Build) -> None:
    _crossing(b, ObjectKind.BICYCLE, CYCLE_MPS, 50.0, True, NEAR_START_M + 0.5)


def _bend_car(b: Build) -> None:
    """A car stopped in the lane on a bend the ego is already driving through."""
    b.road = RoadSpec(curve_start_m=0.0, radius_m=b.pf("radius_m"))
    gap = b.approach()
    car = b.scaled(ObjectKind.CAR, 0.05)
    b.add(ObjectKind.CAR, gap + car[0] / 2, b.draw.jitter(0.0, 0.2), 0.0, car,
          name="stopped car")
    b.until(gap)


def _bend_allowed(v_kph: float, p: Params) -> bool:
    return (v_kph * KPH) ** 2 / abs(float(dict(p)["radius_m"])) <= MAX_LATERAL_MPS2


def _beside(b: Build) -> None:
    """A stationary object whose inner edge is `gap_m` outside the ego's path."""
    kind = ObjectKind(str(b.p("object")))
    size = b.scaled(kind)
    side = 1.0 if b.draw.choice("right", ("left", "right")) == "left" else -1.0
    yaw = b.draw.jitter(0.0, 10.0)
    c, s = abs(math.cos(math.radians(yaw))), abs(math.sin(math.radians(yaw)))
    half = size[0] / 2 * s + size[1] / 2 * c          # the turned footprint's half-width
    station = b.approach()
    b.add(kind, station, side * (EGO_WIDTH_M / 2 + b.pf("gap_m") + half), yaw, size,
          name="beside the path")
    b.until(station + 10.0)


def _oncoming(b: Build) -> None:
    speed = b.pf("oncoming_kph") * KPH
    station = b.approach(b.v + speed, 60.0)
    b.add(ObjectKind.CAR, station, LANE_WIDTH_M + b.draw.jitter(0.0, 0.2), 180.0,
          b.scaled(ObjectKind.CAR, 0.05), Motion(speed_mps=speed, heading_deg=180.0),
          "oncoming car")
    b.until(station, b.v + speed, 2.0)


def _pulling_away(b: Build) -> None:
    gap = b.pf("gap_m") + b.draw.jitter(0.0, 1.0)
    car = b.scaled(ObjectKind.CAR, 0.05)
    b.add(ObjectKind.CAR, gap + car[0] / 2, b.draw.jitter(0.0, 0.1), 0.0, car,
          Motion(speed_mps=b.v + b.pf("faster_kph") * KPH), "lead car pulling away")
    b.duration_s = 8.0


def _override(what: str) -> Callable[[Build], None]:
    """A car stopped in the lane; the driver acts 3.5 s before impact, before AEB's
    brake stages at these speeds, while the car is still in the path when they come:
    `steer` (a swerve into the next lane, the wheel at 250 deg/s), `kickdown` (floored,
    with a gentle lane change below the steering thresholds), `brake` (the pedal, 4
    m/s^2 to a stop). AEB must leave it to the driver: no activation, and the driver's
    own manoeuvre avoids the car."""
    def make(b: Build) -> None:
        gap = b.approach()
        car = b.scaled(ObjectKind.CAR, 0.05)
        b.add(ObjectKind.CAR, gap + car[0] / 2, b.draw.jitter(0.0, 0.1), 0.0, car,
              name="stopped car")
        at = round(max(gap / b.v - 3.5, 0.0) + b.draw.jitter(0.0, 0.1), 2)
        if what == "steer":
            b.driver = DriverSpec(steer_at_s=at, steer_rate_dps=250.0, steer_duration_s=0.4,
                                  lane_change_m=LANE_WIDTH_M, lane_change_s=2.5)
        elif what == "kickdown":
            b.driver = DriverSpec(kickdown_at_s=at, steer_at_s=at, steer_rate_dps=40.0,
                                  steer_duration_s=0.5, lane_change_m=LANE_WIDTH_M,
                                  lane_change_s=2.5)
        else:
            b.driver = DriverSpec(brake_at_s=at, brake_decel_mps2=4.0)
        b.until(gap)
    return make


def _pedestrian_clears(b: Build) -> None:
    """A pedestrian crossing from the near side who has left the ego's path `margin_s`
    before the ego gets there."""
    d = b.draw
    speed = d.jitter(WALK_MPS, 0.1 * WALK_MPS)
    size = b.scaled(ObjectKind.PEDESTRIAN)
    d0 = -d.jitter(NEAR_START_M, 0.5)
    clear_d = EGO_WIDTH_M / 2 + size[0] / 2        # its trailing side past the path's edge
    walk_s = (clear_d - d0) / speed
    station = b.approach(minimum_m=b.v * (walk_s + b.pf("margin_s") + 1.5) + 10.0)
    arrive_t = (station - size[1] / 2) / b.v
    start_t = arrive_t - b.pf("margin_s") - walk_s
    b.add(ObjectKind.PEDESTRIAN, station, d0, 90.0, size,
          Motion(speed_mps=round(speed, 3), heading_deg=90.0,
                 trigger_gap_m=round(station - b.v * start_t, 3),
                 distance_m=round(-d0 + NEAR_START_M, 3)), "pedestrian who clears")
    b.until(station + 5.0)


def _parked_bend(b: Build) -> None:
    """Cars parked along the right edge of a bend the ego drives through (the outside of
    a left bend crosses the straight line ahead)."""
    b.road = RoadSpec(curve_start_m=0.0, radius_m=b.pf("radius_m"))
    d = -(LANE_WIDTH_M / 2 + DEFAULT_SIZE[ObjectKind.CAR][1] / 2 + 0.1)
    start = b.approach(minimum_m=25.0)
    for i in range(4):
        b.add(ObjectKind.CAR, start + i * 6.5 + b.draw.jitter(0.0, 0.5),
              d + b.draw.jitter(0.0, 0.1), b.draw.jitter(0.0, 3.0), name="parked car")
    b.until(start + 30.0)


def _plate(b: Build) -> None:
    size = round(b.draw.uniform(0.8, 0.6, 1.6), 2)
    station = b.pf("range_m") + b.draw.jitter(0.0, 3.0)
    b.add(ObjectKind.PLATE, station, b.draw.jitter(0.0, 0.4), 0.0, (size, size, 0.02),
          name="plate")
    b.until(station + 10.0)


def _sign(b: Build) -> None:
    station = b.approach(minimum_m=45.0)
    b.add(ObjectKind.SIGN, station, b.draw.jitter(0.0, 0.5), 0.0,
          z_m=b.pf("clearance_m"), name="overhead sign")
    b.until(station + 10.0)


def _ghost(b: Build) -> None:
    station = b.pf("range_m") + b.draw.jitter(0.0, 3.0)
    b.add(ObjectKind.GHOST, station, b.draw.jitter(0.0, 0.5), name="multipath ghost")
    b.until(station + 10.0)


def guard_rail(b: Build, radius_m: float, curve_start_m: float, first_m: float,
               last_m: float, offset_m: float = 2.6, segment_m: float = 4.0) -> None:
    """A guard rail of straight segments along the outside edge of a bend, from station
    `first_m` to `last_m` (also for the demo's rail scenario)."""
    b.road = RoadSpec(curve_start_m=curve_start_m, radius_m=radius_m)
    _rail(b, first_m, last_m, -offset_m if radius_m > 0 else offset_m, segment_m)
    b.until(last_m + 10.0)


def _rail(b: Build, first_m: float, last_m: float, d_m: float, segment_m: float = 4.0
          ) -> None:
    """Guard rail segments of about `segment_m` at offset `d_m` from station `first_m`
    to `last_m`, along the road (straight or bending)."""
    n = max(1, round((last_m - first_m) / segment_m))
    length = (last_m - first_m) / n
    for i in range(n):
        b.add(ObjectKind.GUARD_RAIL, first_m + (i + 0.5) * length, d_m, 0.0,
              (round(length, 3), 0.1, 0.75), name="guard rail")


def _rail_bend(b: Build) -> None:
    start = round(b.draw.uniform(20.0, 10.0, 30.0), 1)
    guard_rail(b, b.pf("radius_m"), start, 8.0, start + 45.0)


RAIL_OFFSET_M = 2.6      # a guard rail's offset from the lane's centre (the bend family's)
RAIL_MIN_M = 20.0        # the straight rail's families: at least this much rail from 8 m


def _rail_side(b: Build) -> float:
    """The side a straight rail stands on: right (-1) nominally, either in variants."""
    return 1.0 if b.draw.choice("right", ("left", "right")) == "left" else -1.0


def _rail_end_car(b: Build) -> None:
    """A straight road with a straight guard rail along its edge that ends `beyond_m`
    before a car stopped in the lane: the rail's returns run along the road and end, the
    car stands where the line of the rail does not go."""
    beyond = b.pf("beyond_m") + b.draw.jitter(0.0, 1.0)
    gap = max(b.approach(), 8.0 + RAIL_MIN_M + beyond)
    car = b.scaled(ObjectKind.CAR, 0.05)
    b.add(ObjectKind.CAR, gap + car[0] / 2, b.draw.jitter(0.0, 0.2), 0.0, car,
          name="stopped car")
    _rail(b, 8.0, gap - beyond, _rail_side(b) * b.draw.jitter(RAIL_OFFSET_M, 0.2))
    b.until(gap)


def _rail_beside_car(b: Build) -> None:
    """A car stopped in the lane (offset by the overlap) beside a straight guard rail that
    runs along the road's edge past it."""
    gap = b.approach()
    car = b.scaled(ObjectKind.CAR, 0.05)
    b.add(ObjectKind.CAR, gap + car[0] / 2, _offset_m(b), 0.0, car, name="stopped car")
    _rail(b, 8.0, gap + 20.0, _rail_side(b) * b.draw.jitter(RAIL_OFFSET_M, 0.2))
    b.until(gap)


STANDING_POSES = {"facing": 180.0, "side-on": 90.0}


def _standing(b: Build) -> None:
    """An obstacle standing in the lane, facing the ego or side-on."""
    kind = ObjectKind(str(b.p("object")))
    size = _sized(b, kind)
    yaw = STANDING_POSES[str(b.p("pose"))]
    if kind is ObjectKind.BOX:
        yaw = 0.0 if b.p("pose") == "facing" else 45.0
    station = b.approach(minimum_m=25.0)
    b.add(kind, station, b.draw.jitter(0.0, 0.4), b.draw.jitter(yaw, 10.0), size,
          name="obstacle")
    b.until(station)


def _sized(b: Build, kind: ObjectKind) -> tuple[float, float, float]:
    """A kind's size scaled to the case's `size_m` (its height; a box's edge), drawn
    within 0.4-2 m around it in variants."""
    length, width, height = DEFAULT_SIZE[kind]
    target = min(max(b.draw.jitter(b.pf("size_m"), 0.2 * b.pf("size_m")), 0.4), 2.0)
    if kind is ObjectKind.BOX:
        edge = round(target, 3)
        return (edge, edge, edge)
    k = target / height
    return (round(length * k, 3), round(width * k, 3), round(target, 3))


CROSSING_SPEEDS = {ObjectKind.PEDESTRIAN: WALK_MPS, ObjectKind.BICYCLE: CYCLE_MPS,
                   ObjectKind.CAR: 15 * KPH, ObjectKind.BOX: 1.0}


def _obstacle_crossing(b: Build) -> None:
    kind = ObjectKind(str(b.p("object")))
    from_right = b.p("side") == "near"
    start = NEAR_START_M if from_right else FAR_START_M
    if kind is ObjectKind.CAR:
        start += 2.0
    _crossing(b, kind, CROSSING_SPEEDS[kind], 50.0, from_right, start, name="obstacle")


# -- the families ---------------------------------------------------------------------------

def _points(**axes: Sequence[ParamValue]) -> tuple[Params, ...]:
    """Every combination of the axes' values, keys in the given order."""
    keys = list(axes)
    out: list[Params] = [()]
    for k in keys:
        out = [(*p, (k, v)) for p in out for v in axes[k]]
    return tuple(out)


NO_PARAMS: tuple[Params, ...] = ((),)     # a family with speed as its only axis
OFFSETS = (-50.0, -25.0, 0.0, 25.0, 50.0)
RADII = (-250.0, -100.0, -50.0, 50.0, 100.0, 250.0)
STANDING = (tuple((("object", "box"), ("size_m", s), ("pose", p), ("light", li))
                  for s in (0.4, 0.8, 1.5) for p in STANDING_POSES for li in ("day", "dusk"))
            + tuple((("object", k), ("size_m", s), ("pose", p), ("light", li))
                    for k, sizes in (("pedestrian", (1.15, 1.8)), ("bicycle", (1.8,)),
                                     ("car", (1.5,)))
                    for s in sizes for p in STANDING_POSES for li in ("day", "dusk")))

def _ahead(name: str, kind: ObjectKind, speed_mps: float, impact: float,
           lights: tuple[str, ...] = ()) -> Family:
    """A Euro NCAP longitudinal family: the target ahead in the ego's direction."""
    who = "An adult walks" if kind is ObjectKind.PEDESTRIAN else "A cyclist rides"
    axes: dict[str, Sequence[ParamValue]] = {"impact": (impact,)}
    if lights:
        axes["light"] = lights
    return Family(name, ScenarioKind.THREAT, "euro_ncap",
                  f"{who} ({speed_mps * 3.6:.0f} km/h) ahead in the ego's direction, at "
                  f"{impact:g} % of its width.", ALL_SPEEDS[1:], _points(**axes),
                  _longitudinal(kind, speed_mps))


_FAMILY_LIST = [
    Family("CCRs", ScenarioKind.THREAT, "euro_ncap",
           "Car-to-car rear, stationary: a car stopped in the lane, offset by the overlap.",
           ALL_SPEEDS, _points(offset=OFFSETS), _ccr_stationary),
    Family("CCRm", ScenarioKind.THREAT, "euro_ncap",
           "Car-to-car rear, moving: a slower lead car (20 km/h), offset by the overlap.",
           ALL_SPEEDS[2:], _points(offset=OFFSETS), _ccr_moving),
    Family("CCRb", ScenarioKind.THREAT, "euro_ncap",
           "Car-to-car rear, braking: the lead car at the ego's speed brakes to a stop.",
           (50.0,), _points(decel_mps2=(2.0, 6.0), gap_m=(12.0, 40.0)), _ccr_braking),
    Family("CPNA-25", ScenarioKind.THREAT, "euro_ncap",
           "An adult walks (5 km/h) from the near side, hit at 25 % of the ego's front.",
           ALL_SPEEDS, _points(light=("day", "night")),
           _pedestrian_crossing(25.0, True, WALK_MPS, NEAR_START_M)),
    Family("CPNA-75", ScenarioKind.THREAT, "euro_ncap",
           "An adult walks (5 km/h) from the near side, hit at 75 % of the ego's front.",
           ALL_SPEEDS, NO_PARAMS, _pedestrian_crossing(75.0, True, WALK_MPS, NEAR_START_M)),
    Family("CPFA-50", ScenarioKind.THREAT, "euro_ncap",
           "An adult walks (8 km/h) from the far side, hit at 50 % of the ego's front.",
           ALL_SPEEDS, NO_PARAMS, _pedestrian_crossing(50.0, False, FAR_WALK_MPS, FAR_START_M)),
    Family("CPNC-50", ScenarioKind.THREAT, "euro_ncap",
           "A child runs (5 km/h) out from in front of cars parked on the near side, hit at "
           "50 %.", ALL_SPEEDS, NO_PARAMS, _child_behind_cars),
    _ahead("CPLA-25", ObjectKind.PEDESTRIAN, WALK_MPS, 25.0, ("day", "night")),
    _ahead("CPLA-50", ObjectKind.PEDESTRIAN, WALK_MPS, 50.0),
    Family("CBNA-50", ScenarioKind.THREAT, "euro_ncap",
           "A cyclist (15 km/h) crosses from the near side, hit at 50 % of the ego's front; "
           "it rides its last 17 m to the impact point at that speed.",
           ALL_SPEEDS, NO_PARAMS, _bicycle_crossing),
    _ahead("CBLA-25", ObjectKind.BICYCLE, CYCLE_MPS, 25.0),
    _ahead("CBLA-50", ObjectKind.BICYCLE, CYCLE_MPS, 50.0),
    Family("bend_stopped_car", ScenarioKind.THREAT, "bend",
           "A car stopped in the lane on a bend (radius signed: positive left) the ego "
           "follows.", ALL_SPEEDS, _points(radius_m=RADII), _bend_car,
           allowed=_bend_allowed),
    Family("rail_end_stopped_car", ScenarioKind.THREAT, "road_edge",
           "A car stopped in the lane of a straight road `beyond_m` past the end of a "
           "straight guard rail along its edge.", ALL_SPEEDS[:4],
           _points(beyond_m=(3.0, 10.0, 20.0)), _rail_end_car),
    Family("rail_beside_stopped_car", ScenarioKind.THREAT, "road_edge",
           "A car stopped in the lane of a straight road (offset by the overlap) beside a "
           "straight guard rail along its edge.", ALL_SPEEDS[:4],
           _points(offset=(-25.0, 0.0, 25.0)), _rail_beside_car),
    Family("beside_path", ScenarioKind.NO_THREAT, "no_threat",
           "A stationary object just outside the ego's path, its inner edge `gap_m` from it.",
           ALL_SPEEDS, _points(object=("car", "pedestrian", "box"),
                               gap_m=(0.3, 0.6, 1.0, 1.5)), _beside),
    Family("oncoming_car", ScenarioKind.NO_THREAT, "no_threat",
           "A car coming the other way in the next lane.",
           ALL_SPEEDS, _points(oncoming_kph=(30.0, 50.0)), _oncoming),
    Family("lead_pulling_away", ScenarioKind.NO_THREAT, "no_threat",
           "A lead car close ahead in the lane, driving away faster than the ego.",
           ALL_SPEEDS, _points(gap_m=(10.0,), faster_kph=(5.0, 10.0, 20.0)), _pulling_away),
    Family("pedestrian_clears", ScenarioKind.NO_THREAT, "no_threat",
           "A pedestrian crossing from the near side who has left the ego's path "
           "`margin_s` before it gets there.",
           ALL_SPEEDS, _points(margin_s=(1.0, 2.0, 3.0)), _pedestrian_clears),
    Family("parked_cars_bend", ScenarioKind.NO_THREAT, "no_threat",
           "Cars parked along the right edge of a bend the ego follows.",
           ALL_SPEEDS, _points(radius_m=(-100.0, -50.0, 50.0, 100.0)), _parked_bend,
           allowed=_bend_allowed),
    Family("plate", ScenarioKind.NO_THREAT, "false_target",
           "A metal plate or manhole cover (0.6-1.6 m) in the lane: a radar return, "
           "nothing to hit.", ALL_SPEEDS, _points(range_m=(25.0, 40.0, 60.0)), _plate),
    Family("overhead_sign", ScenarioKind.NO_THREAT, "false_target",
           "An overhead sign on its gantry, the board `clearance_m` above the road.",
           ALL_SPEEDS, _points(clearance_m=(4.0, 5.0, 6.0, 7.0)), _sign),
    Family("ghost", ScenarioKind.NO_THREAT, "false_target",
           "A persistent multipath ghost in the lane: the radar reports what is not there.",
           ALL_SPEEDS, _points(range_m=(20.0, 30.0, 45.0)), _ghost),
    Family("guard_rail_bend", ScenarioKind.NO_THREAT, "false_target",
           "A guard rail along the outside edge of a bend the ego approaches and follows: "
           "it crosses the straight line ahead.", ALL_SPEEDS,
           _points(radius_m=(-100.0, -50.0, 50.0, 100.0)), _rail_bend, allowed=_bend_allowed),
    Family("override_steer", ScenarioKind.NO_THREAT, "override",
           "The driver swerves round a car stopped in the lane (wheel at 250 deg/s): "
           "AEB is suppressed.", ALL_SPEEDS[2:], NO_PARAMS, _override("steer")),
    Family("override_kickdown", ScenarioKind.NO_THREAT, "override",
           "The driver floors the accelerator (kick-down) and changes lanes gently past a "
           "car stopped in the lane: AEB is suppressed.", ALL_SPEEDS[2:], NO_PARAMS,
           _override("kickdown")),
    Family("override_brake", ScenarioKind.NO_THREAT, "override",
           "The driver brakes (4 m/s^2) for a car stopped in the lane: AEB leaves the "
           "stop to the driver.", ALL_SPEEDS[2:], NO_PARAMS, _override("brake")),
    Family("obstacle_standing", ScenarioKind.THREAT, "obstacle",
           "An obstacle of every kind the simulator has standing in the lane (0.4-2 m), "
           "facing the ego or side-on, by day or at dusk.",
           ALL_SPEEDS[:3], STANDING, _standing),
    Family("cyclist_from_kerb", ScenarioKind.THREAT, "obstacle",
           "Not a Euro NCAP case: a cyclist waiting at the near kerb, 5 m from the ego's "
           "centre, sets off at 15 km/h about 1.2 s before the ego arrives; hit at 50 %.",
           ALL_SPEEDS, NO_PARAMS, _cyclist_from_kerb),
    Family("obstacle_crossing", ScenarioKind.THREAT, "obstacle",
           "An obstacle of every kind crossing the ego's path from the near or far side, "
           "hit at 50 %, by day or at dusk.", ALL_SPEEDS[:3],
           _points(object=("pedestrian", "bicycle", "car", "box"), side=("near", "far"),
                   light=("day", "dusk")), _obstacle_crossing),
]
FAMILIES: dict[str, Family] = {f.name: f for f in _FAMILY_LIST}


def all_cases(seeds: Sequence[int] = (0,), families: Sequence[str] | None = None
              ) -> Iterator[Case]:
    """Every case of the named families (all when None) at every grid point and seed.
    Raises KeyError for an unknown family."""
    for name in families or list(FAMILIES):
        yield from FAMILIES[name].cases(seeds)


def case_of(family: str, speed_kph: float, seed: int = 0, **params: ParamValue) -> Case:
    """A case of `family` at one grid point (parameters as values or as text). Raises
    KeyError for an unknown family and ValueError for a point not in its grid."""
    fam = FAMILIES[family]
    for v, p in fam.grid():
        if v == speed_kph and _point_matches(p, params, every=True):
            return Case(family, v, p, seed)
    raise ValueError(f"{family} has no grid point at {speed_kph:g} km/h with {params} "
                     f"(speeds {', '.join(f'{v:g}' for v in fam.speeds_kph)}; points "
                     f"{[dict(p) for p in fam.points]})")


def _point_matches(point: Params, wanted: dict[str, ParamValue], every: bool = False) -> bool:
    """Whether a grid point has the wanted values (numbers compared as numbers); with
    `every`, also no other parameter."""
    have = dict(point)
    if every and set(have) != set(wanted):
        return False
    for key, value in wanted.items():
        if key not in have:
            return False
        mine = have[key]
        if isinstance(mine, float):
            try:
                if float(value) != mine:
                    return False
            except ValueError:
                return False
        elif str(value) != mine:
            return False
    return True


# -- command line -----------------------------------------------------------------------------

def listing() -> str:
    lines = [f"{'family':<18} {'kind':<9} {'group':<12} {'km/h':<17} {'cases':>5}  parameters",
             "-" * 100]
    for f in FAMILIES.values():
        speeds = ",".join(f"{v:g}" for v in f.speeds_kph)
        axes: dict[str, list[str]] = {}
        for p in f.points:
            for k, v in p:
                axes.setdefault(k, [])
                if _fmt(v) not in axes[k]:
                    axes[k].append(_fmt(v))
        params = "; ".join(f"{k} {'/'.join(v)}" for k, v in axes.items()) or "-"
        lines.append(f"{f.name:<18} {f.kind.value:<9} {f.group:<12} {speeds:<17} "
                     f"{len(f.grid()):>5}  {params}")
    total = sum(len(f.grid()) for f in FAMILIES.values())
    lines += ["-" * 100, f"{len(FAMILIES)} families, {total} nominal cases; seeds: "
              f"{describe_splits()}"]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m aeb_radar_camera.tools.sim.families",
                                 description="SIMULATION test cases: list the scenario "
                                 "families, show or write cases as scenario TOML files.")
    ap.add_argument("--list", action="store_true", help="the families and their grids")
    ap.add_argument("--family", action="append", help="a family (repeatable; default all)")
    ap.add_argument("--speed", type=float, action="append", help="ego speed, km/h (repeatable)")
    ap.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                    help="only grid points with this parameter value (repeatable)")
    ap.add_argument("--seeds", default="nominal",
                    help="nominal | train:N | heldout:N | A-B | a,b,c (default nominal)")
    ap.add_argument("--show", action="store_true", help="print the cases' TOML")
    ap.add_argument("--write", type=Path, metavar="DIR", help="write <name>.toml files here")
    args = ap.parse_args(argv)
    if args.list or not (args.show or args.write):
        print(listing())
        if not (args.show or args.write):
            return 0
    try:
        seeds = seeds_of(args.seeds)
        wanted: dict[str, ParamValue] = dict(p.split("=", 1) for p in args.param)
        cases = [c for c in all_cases(seeds, args.family)
                 if (not args.speed or c.speed_kph in args.speed)
                 and _point_matches(c.params, wanted)]
    except (KeyError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if not cases:
        print("error: no case matches", file=sys.stderr)
        return 2
    for i, case in enumerate(cases, 1):
        sc = case.scenario()
        if args.show:
            print(f"# {case.name} ({split_of(case.seed)})\n{scenario_toml(sc)}")
        if args.write:
            path = write_scenario(sc, args.write)
            print(f"[{i}/{len(cases)}] {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
