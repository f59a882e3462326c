"""Scenarios as data: TOML files under tools/sim/scenarios/ (and the cases of the family
generator, tools/sim/families.py), validated at load.

Objects are placed in road coordinates (tools/sim/road.py): `x_m` is the station along
the ego lane's centre line (from below the ego's radar at t = 0), `y_m` the lateral
offset from it (left positive), `yaw_deg` turns the body from the road's tangent there
(0: lengthwise along the road, 90: across it), a motion's `heading_deg` likewise. On a
straight road (no `[road]` radius) these are the world frame: x along the road, y left.
The ego follows the lane centre (lane keeping). See docs/simulator.md for the format.
"""

import enum
from pathlib import Path
from typing import Annotated, Any

import msgspec

from aeb_radar_camera.common.config.loader import ConfigError, load_config
from aeb_radar_camera.tools.messages import Lighting, ObjectKind, RoadGeometry

SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"

Positive = Annotated[float, msgspec.Meta(gt=0)]
NonNeg = Annotated[float, msgspec.Meta(ge=0)]


class ScenarioKind(enum.Enum):
    THREAT = "threat"          # a brake is needed: pass iff no collision
    NO_THREAT = "no_threat"    # no brake is needed: pass iff no brake was applied


# length (along the body), width, height in metres
DEFAULT_SIZE: dict[ObjectKind, tuple[float, float, float]] = {
    ObjectKind.CAR: (4.4, 1.8, 1.5),
    ObjectKind.BOX: (0.6, 0.6, 0.6),
    ObjectKind.PEDESTRIAN: (0.35, 0.55, 1.75),
    ObjectKind.BICYCLE: (1.75, 0.6, 1.75),
    ObjectKind.PLATE: (0.8, 0.8, 0.02),        # a manhole cover's 0.8 m
    ObjectKind.SIGN: (0.2, 9.0, 1.6),          # the board: across the road, 1.6 m tall
    ObjectKind.GUARD_RAIL: (4.0, 0.1, 0.75),   # a W-beam segment, its top 0.75 m high
    ObjectKind.GHOST: (0.2, 0.2, 0.2),         # where the radar puts it; nothing is there
}
# Height of the bottom above the road (a sign's clearance); 0 for everything else.
DEFAULT_Z_M: dict[ObjectKind, float] = {ObjectKind.SIGN: 5.0}


class Motion(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Motion at `speed_mps` in a direction relative to the road (a car with heading 0
    follows its lane through a bend), optionally started by the ego's approach, limited in
    distance (a pedestrian who steps into the lane and stops), and ended by braking at
    `decel_mps2` to a stop, `brake_after_s` after it started (a lead car that brakes)."""

    speed_mps: NonNeg
    heading_deg: float = 0.0             # direction of travel: 0 forward, 90 left, -90 right
    trigger_gap_m: NonNeg | None = None  # start when ego station >= object station - gap;
    #                                      None: at t = 0
    distance_m: Positive | None = None   # stop after this far; None: never
    brake_after_s: NonNeg | None = None  # then brake at decel_mps2 to a stop
    decel_mps2: Annotated[float, msgspec.Meta(gt=0, le=12)] | None = None

    def __post_init__(self) -> None:
        if (self.brake_after_s is None) != (self.decel_mps2 is None):
            raise ValueError("motion.brake_after_s and motion.decel_mps2 go together")


class SceneObject(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    kind: ObjectKind
    x_m: float
    y_m: float = 0.0
    yaw_deg: float = 0.0
    size_m: tuple[Positive, Positive, Positive] | None = None   # length, width, height
    motion: Motion | None = None
    name: str = ""
    z_m: NonNeg | None = None            # bottom above the road; None: the kind's default

    def size(self) -> tuple[float, float, float]:
        return self.size_m or DEFAULT_SIZE[self.kind]

    def elevation(self) -> float:
        return self.z_m if self.z_m is not None else DEFAULT_Z_M.get(self.kind, 0.0)


class EgoSpec(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The ego vehicle (defaults: a car 1.8 m wide, as fusion's default corridor assumes).

    Deceleration follows the actuator's brake position: decel = max_decel * position/100,
    through a first-order lag `brake_lag_s` (brake line and tyres). Without braking the
    ego keeps its speed (a driver holding the throttle); it never re-accelerates after
    braking.
    """

    speed_kph: Annotated[float, msgspec.Meta(ge=10, le=60)]   # Euro NCAP's AEB range
    width_m: Positive = 1.8
    length_m: Positive = 4.2
    max_decel_mps2: Positive = 6.0
    brake_lag_s: NonNeg = 0.15


class DriverSpec(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """`[driver]`: what the simulated driver does, each from a time into the run (None:
    never). Without it the driver holds the throttle part-way (`accelerator_pct`), keeps
    the lane with the wheel (its angle follows the road through a bicycle model) and
    never brakes.

    - `kickdown_at_s`: the accelerator floored (kick-down switch) from then on; the ego
      keeps its speed (the simulated car does not accelerate).
    - `steer_at_s`: a steering manoeuvre: the wheel turned at `steer_rate_dps` for
      `steer_duration_s`, then held; with `lane_change_m` the ego moves that far
      sideways (left positive) over `lane_change_s` (a smooth S, its heading kept along
      the road), else it keeps its lane.
    - `brake_at_s`: the brake pedal pressed from then on, decelerating the ego at
      `brake_decel_mps2` (or the actuator's, whichever is larger)."""

    accelerator_pct: Annotated[float, msgspec.Meta(ge=0, le=100)] = 20.0
    kickdown_at_s: NonNeg | None = None
    steer_at_s: NonNeg | None = None
    steer_rate_dps: Annotated[float, msgspec.Meta(ge=-1000, le=1000)] = 300.0
    steer_duration_s: Positive = 0.4
    lane_change_m: Annotated[float, msgspec.Meta(ge=-5, le=5)] = 0.0
    lane_change_s: Positive = 2.0
    brake_at_s: NonNeg | None = None
    brake_decel_mps2: Annotated[float, msgspec.Meta(gt=0, le=12)] = 4.0


class CameraLook(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """How the rendered scene looks: `brightness` scales the light (1 day, 0.3 dusk),
    `noise` is the sensor noise standard deviation in grey levels."""

    brightness: Annotated[float, msgspec.Meta(gt=0, le=2)] = 1.0
    noise: Annotated[float, msgspec.Meta(ge=0, le=30)] = 2.0


class RadarLook(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """The simulated ARS408's output and imperfections."""

    mode: str = "objects"                 # objects | clusters
    range_sigma_m: NonNeg = 0.10
    lateral_sigma_m: NonNeg = 0.15
    velocity_sigma_mps: NonNeg = 0.10
    rcs_sigma_dbsm: NonNeg = 2.0
    ghost_rate_per_cycle: Annotated[float, msgspec.Meta(ge=0, le=5)] = 0.3
    split_probability: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.15   # objects mode
    dropout_probability: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.02
    id_swap_probability: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.01
    # Short-lived low-RCS returns near the radar per cycle (rain, spray); rain adds its own.
    clutter_per_cycle: Annotated[float, msgspec.Meta(ge=0, le=20)] = 0.0

    def __post_init__(self) -> None:
        if self.mode not in ("objects", "clusters"):
            raise ValueError(f"radar.mode {self.mode!r}: expected 'objects' or 'clusters'")


MIN_RADIUS_M = 50.0


class RoadSpec(RoadGeometry, frozen=True, forbid_unknown_fields=True):
    """`[road]`: the lane centre line (RoadGeometry, as `sim/world` carries it), checked:
    a bend of at least MIN_RADIUS_M either way."""

    def __post_init__(self) -> None:
        if self.curve_start_m < 0:
            raise ValueError(f"road.curve_start_m {self.curve_start_m:g}: not before the start")
        if self.radius_m is not None and abs(self.radius_m) < MIN_RADIUS_M:
            raise ValueError(f"road.radius_m {self.radius_m:g}: at least {MIN_RADIUS_M:g} m "
                             "either way (negative: a right bend)")


# What rain does to the radar: clutter returns per cycle and noise (times the look's).
RAIN_CLUTTER_PER_CYCLE = 3.0
RAIN_NOISE_FACTOR = 1.5


class Scenario(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    name: str
    kind: ScenarioKind
    ego: EgoSpec
    object: tuple[SceneObject, ...]
    description: str = ""
    duration_s: Annotated[float, msgspec.Meta(gt=0, le=120)] = 20.0
    seed: int = 0
    lighting: Lighting = Lighting.DAY
    road: RoadSpec = msgspec.field(default_factory=RoadSpec)
    radar: RadarLook = msgspec.field(default_factory=RadarLook)
    camera: CameraLook = msgspec.field(default_factory=CameraLook)
    driver: DriverSpec = msgspec.field(default_factory=DriverSpec)

    def radar_look(self) -> RadarLook:
        """The radar's look in this scenario's weather: rain adds clutter and noise."""
        if self.lighting is not Lighting.RAIN:
            return self.radar
        r = self.radar
        return msgspec.structs.replace(
            r, clutter_per_cycle=r.clutter_per_cycle + RAIN_CLUTTER_PER_CYCLE,
            range_sigma_m=r.range_sigma_m * RAIN_NOISE_FACTOR,
            lateral_sigma_m=r.lateral_sigma_m * RAIN_NOISE_FACTOR)

    def __post_init__(self) -> None:
        if not self.object:
            raise ValueError("a scenario needs at least one [[object]]")
        for i, obj in enumerate(self.object):
            if obj.x_m <= 0:
                raise ValueError(f"object[{i}] ({obj.kind.value}) must start ahead of the "
                                 f"ego (x_m > 0), got {obj.x_m}")


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario file. Raises ConfigError naming the file and field."""
    return load_config(path, Scenario, what="scenario")


def _plain(value: Any) -> Any:
    """A struct as TOML data without the fields at their defaults (TOML has no null:
    absent fields take their defaults again when read back)."""
    if isinstance(value, msgspec.Struct):
        out = {}
        for f in msgspec.structs.fields(value):
            v = getattr(value, f.name)
            default = (f.default if f.default is not msgspec.NODEFAULT else
                       f.default_factory() if f.default_factory is not msgspec.NODEFAULT
                       else msgspec.NODEFAULT)
            if v is None or (default is not msgspec.NODEFAULT and v == default):
                continue
            out[f.encode_name] = _plain(v)
        return out
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, enum.Enum):
        return value.value
    return value


def scenario_toml(scenario: Scenario) -> str:
    """The scenario as a TOML file's text, fields at their defaults left out
    (`load_scenario` reads it back equal)."""
    return msgspec.toml.encode(_plain(scenario)).decode()


def write_scenario(scenario: Scenario, folder: str | Path) -> Path:
    """Write `<folder>/<name>.toml`; returns its path. Raises OSError."""
    path = Path(folder) / f"{scenario.name}.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(scenario_toml(scenario))
    return path


def find_scenario(name_or_path: str) -> Path:
    """A scenario by file path or by name in tools/sim/scenarios/. Raises ConfigError."""
    p = Path(name_or_path)
    if p.is_file():
        return p
    candidate = SCENARIO_DIR / f"{name_or_path}.toml"
    if candidate.is_file():
        return candidate
    known = ", ".join(sorted(f.stem for f in SCENARIO_DIR.glob("*.toml")))
    raise ConfigError(f"no scenario {name_or_path!r} (a file, or one of: {known})")


def all_scenarios() -> list[Path]:
    return sorted(SCENARIO_DIR.glob("*.toml"))


# `aeb demo`'s default set (and the recordings `aeb eval` makes of it).
DEMO_SCENARIOS = (
    "stationary_car_30kph",
    "cardboard_box_30kph",
    "pedestrian_standing_20kph",
    "pedestrian_crossing_20kph",
    "bicycle_crossing_20kph",
    "pedestrian_behind_parked_car_20kph",
    "bicycle_ahead_slow_20kph",
    "multi_object_25kph",
    "no_threat_parked_cars_30kph",
    "no_threat_pedestrian_walking_beside_20kph",
    "no_threat_pedestrian_crossed_20kph",
    "no_threat_manhole_30kph",
    "no_threat_overhead_sign_30kph",
    "no_threat_guard_rail_bend_20kph",
    "no_threat_multipath_ghost_20kph",
)


def pick_scenarios(spec: str) -> list[Scenario]:
    """Scenarios by comma-separated names or files, or "all". Raises ConfigError naming an
    unknown or invalid scenario."""
    paths = all_scenarios() if spec == "all" else [
        find_scenario(name.strip()) for name in spec.split(",") if name.strip()]
    if not paths:
        raise ConfigError("no scenario selected")
    return [load_scenario(p) for p in paths]
