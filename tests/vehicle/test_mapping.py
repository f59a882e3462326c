"""The gateway's configuration against the DBC: every name checked at start with a message
that says what is wrong; the shipped configs valid and mapping the same signals; a DBC
that cannot be read is a configuration error."""

import math

import msgspec
import pytest

from aeb_radar_camera.common.config.loader import ConfigError, load_config, parse_config
from aeb_radar_camera.common.config.vehicle import VehicleConfig
from aeb_radar_camera.common.messages.vehicle import EgoMotion, Gear
from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.services.vehicle.core import VehicleCore
from aeb_radar_camera.services.vehicle.dbc import load_dbc
from aeb_radar_camera.services.vehicle.mapping import MappingError, build_plan
from tests.vehicle.helpers import DB, SHIPPED, WALL0, settings

# Two messages with a signal of the same name, and a float signal.
SMALL_DBC = """VERSION ""
BS_:
BU_: A
BO_ 256 Left: 8 A
 SG_ Speed : 0|16@1+ (0.01,0) [0|655.35] "km/h" A
 SG_ Code : 16|3@1+ (1,0) [0|7] "" A
BO_ 257 Right: 8 A
 SG_ Speed : 0|16@1+ (0.01,0) [0|655.35] "km/h" A
 SG_ Yaw : 32|32@1- (1,0) [-1e9|1e9] "deg/s" A
SIG_VALTYPE_ 257 Yaw : 1;
"""


def test_the_shipped_configs_are_valid_and_map_the_same_signals():
    replay = load_config(DEPLOY / "vehicle-replay.toml", VehicleConfig).gateway
    assert replay.can.interface == "replay"
    assert (replay.motion, replay.driver, replay.dbc) == (SHIPPED.motion, SHIPPED.driver,
                                                          SHIPPED.dbc)
    plan = build_plan(DB, SHIPPED)
    assert [m.key for m in plan.messages] == ["motion", "driver"]
    assert {s.ref for s in plan.slots} == {
        "VehicleSpeed.VehicleSpeed", "YawRate.YawRate", "Gear.GearLever",
        "SteeringWheel.SteeringWheelAngle", "SteeringWheel.SteeringWheelRate",
        "Pedals.AcceleratorPedal", "Pedals.Kickdown", "Brake.BrakePedalPressed",
        "Brake.BrakePressure"}
    assert plan.ignored_ids == {(DB.get_message_by_name(n).frame_id, False)
                                for n in ("WheelSpeeds", "Engine")}


@pytest.mark.parametrize(("motion", "message"), [
    ({"speed": {"signal": "Nope.VehicleSpeed"}, "yaw_rate": {"signal": "YawRate"}},
     "gateway.motion.speed: the DBC has no message 'Nope'"),
    ({"speed": {"signal": "VehicleSpeed.Speed"}, "yaw_rate": {"signal": "YawRate"}},
     "message VehicleSpeed has no signal 'Speed' (it has: VehicleSpeed, StandStill"),
    ({"speed": {"signal": "VehicleSpeed"}, "yaw_rate": {"signal": "Yaw"}},
     "gateway.motion.yaw_rate: the DBC has no signal 'Yaw'"),
])
def test_a_name_the_dbc_does_not_have_is_an_error_naming_it(motion, message):
    with pytest.raises(MappingError) as exc:
        build_plan(DB, settings(motion={**motion, "reverse_from_gear": False}))
    assert message in str(exc.value)


def test_a_bare_name_in_two_messages_must_name_its_message(tmp_path):
    path = tmp_path / "small.dbc"
    path.write_text(SMALL_DBC)
    db = load_dbc(str(path))
    gateway = settings(dbc=str(path), driver={"publish": False},
                       motion={"speed": {"signal": "Speed"},
                               "yaw_rate": {"signal": "Yaw"}, "reverse_from_gear": False})
    with pytest.raises(MappingError, match=r"in several messages \(Left, Right\)"):
        build_plan(db, gateway)
    ok = settings(dbc=str(path), driver={"publish": False},
                  motion={"speed": {"signal": "Right.Speed"}, "yaw_rate": {"signal": "Yaw"},
                          "reverse_from_gear": False})
    core = VehicleCore(ok, db)
    right = db.get_message_by_name("Right")
    for yaw in (math.nan, math.inf, 3.0):
        core.on_frame(right.frame_id, right.encode({"Speed": 1.0, "Yaw": yaw}, strict=False), False,
                      WALL0, 1)
    assert core.rejected.snapshot() == {"not_finite:yaw_rate_dps": 2}
    [(_, motion)] = core.poll(1, WALL0)
    assert isinstance(motion, EgoMotion) and motion.yaw_rate_dps == 3.0


def test_gear_values_by_the_dbcs_names_or_raw_numbers():
    named = build_plan(DB, SHIPPED)
    gear = next(s for s in named.slots if s.ref == "Gear.GearLever")
    assert gear.gears == {0: Gear.PARK, 1: Gear.REVERSE, 2: Gear.NEUTRAL, 3: Gear.DRIVE}
    numbers = settings(driver={"gear": {"signal": "GearLever", "max_age_s": 0.35,
                                        "values": {"0x0": "park", "3": "drive"}}})
    gear = next(s for s in build_plan(DB, numbers).slots if s.ref == "Gear.GearLever")
    assert gear.gears == {0: Gear.PARK, 3: Gear.DRIVE}
    with pytest.raises(MappingError, match=r"'S' is neither a number nor one of the DBC's "
                                           r"names for GearLever \(D, Invalid, N, P, R\)"):
        build_plan(DB, settings(driver={"gear": {"signal": "GearLever",
                                                 "values": {"S": "drive"}}}))


@pytest.mark.parametrize(("gateway", "named"), [
    ({"dbc": ""}, "gateway.dbc must name the car's DBC file"),
    ({"motion": {"yaw_rate": {"signal": "YawRate"}}}, "motion needs speed and yaw_rate"),
    ({"driver": {"publish": True}}, "driver needs at least one field mapped"),
    ({"driver": {"accelerator_pedal": {"signal": "AcceleratorPedal"}}},
     "motion.reverse_from_gear needs driver.gear mapped"),
    ({"driver": {"gear": {"signal": "GearLever", "values": {"D": "sport"}}}},
     "['sport'] are not gears"),
    ({"driver": {"kickdown": {"signal": ["Kickdown", "AcceleratorPedal"]}}},
     "a flag comes from one signal"),
    ({"motion": {"speed": {"signal": "VehicleSpeed", "scale": 0},
                 "yaw_rate": {"signal": "YawRate"}}}, "scale must not be 0"),
    ({"motion": {"speed": {"signal": "VehicleSpeed", "min": 5, "max": 1},
                 "yaw_rate": {"signal": "YawRate"}}}, "max must be >= min"),
    ({"motion": {"publish": False}, "driver": {"publish": False}}, "publishes nothing"),
    ({"can": {"interface": "replay"}}, "needs replay.file"),
    ({"signal_max_age_s": 0}, "signal_max_age_s"),
])
def test_an_invalid_table_fails_naming_what_is_wrong(gateway, named):
    base = msgspec.to_builtins(SHIPPED)
    base.update(gateway)
    with pytest.raises(ConfigError) as exc:
        parse_config({"gateway": base}, VehicleConfig)
    assert named in str(exc.value)


def test_a_dbc_that_cannot_be_read_is_a_mapping_error(tmp_path):
    with pytest.raises(MappingError, match="No such file"):
        load_dbc(str(tmp_path / "missing.dbc"))
    garbage = tmp_path / "garbage.dbc"
    garbage.write_bytes(b"BO_ this is not a DBC \xff\x00")
    with pytest.raises(MappingError, match="is not a CAN database cantools reads"):
        load_dbc(str(garbage))


def test_without_a_gateway_table_the_error_names_it():
    with pytest.raises(ConfigError, match="missing required field `gateway`"):
        parse_config({}, VehicleConfig)
    with pytest.raises(ConfigError, match="motion needs speed and yaw_rate"):
        parse_config({"gateway": {"dbc": "car.dbc"}}, VehicleConfig)
