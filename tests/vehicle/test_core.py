"""The gateway's pure core on frames encoded with cantools: values converted as mapped,
messages at their rate and only while every signal is fresh, the oldest value's stamp,
bad frames and values counted and never raised, readiness."""

import random

import msgspec
import pytest

from aeb_radar_camera.common.messages.radar import BUS_NOT_READY, BusState
from aeb_radar_camera.common.messages.vehicle import DriverInputs, EgoMotion, Gear
from tests.vehicle.helpers import DB, MS, SHIPPED, WALL0, Fed, frame, settings

KPH = SHIPPED.motion.speed.scale if SHIPPED.motion.speed else 0.0


def by_key(out):
    return {key: msg for key, msg in out}


def test_values_are_converted_as_mapped():
    fed = Fed()
    fed.all_signals(kph=36.0)
    out = by_key(fed.poll())
    motion, driver = out["vehicle/motion"], out["vehicle/driver"]
    assert isinstance(motion, EgoMotion) and isinstance(driver, DriverInputs)
    assert motion.speed_mps == KPH * 36.0 == pytest.approx(10.0)
    assert motion.yaw_rate_dps == 2.5
    assert driver.steering_wheel_angle_deg == -12.5
    assert driver.steering_wheel_rate_dps == 4.0
    assert driver.accelerator_pedal_pct == 40.0
    assert driver.kickdown is False and driver.brake_pedal_pressed is False
    assert driver.brake_pressure_bar == 0.0
    assert driver.gear is Gear.DRIVE
    assert motion.header.source == driver.header.source == "vehicle/main"
    assert motion.header.pub_mono_ns == fed.mono


def test_reverse_gear_makes_the_unsigned_speed_negative():
    fed = Fed()
    fed.all_signals(kph=5.4, gear=1)
    out = by_key(fed.poll())
    assert out["vehicle/motion"].speed_mps == pytest.approx(-1.5)
    assert out["vehicle/driver"].gear is Gear.REVERSE


def test_a_speed_from_the_mean_of_two_wheels():
    gateway = settings(motion={"reverse_from_gear": False, "yaw_rate": {"signal": "YawRate"},
                               "speed": {"signal": ["WheelSpeed_RL", "WheelSpeed_RR"],
                                         "scale": KPH}})
    fed = Fed(gateway)
    fed.all_signals()
    fed.send("WheelSpeeds", WheelSpeed_RL=30.0, WheelSpeed_RR=32.0, WheelSpeed_FL=99.0)
    assert by_key(fed.poll())["vehicle/motion"].speed_mps == pytest.approx(31.0 * KPH)


def test_brake_pressed_from_a_pressure_threshold():
    gateway = settings(driver={"brake_pedal_pressed": {"signal": "BrakePressure",
                                                       "above": 2.0},
                               "gear": msgspec.to_builtins(SHIPPED.driver.gear)})
    fed = Fed(gateway)
    for bar, pressed in ((1.5, False), (2.5, True)):
        fed.advance(20)
        fed.all_signals()
        fed.send("Brake", BrakePressure=bar, BrakePedalPressed=0)
        driver = by_key(fed.poll())["vehicle/driver"]
        assert driver.brake_pedal_pressed is pressed
        assert driver.accelerator_pedal_pct is None   # not mapped in this table


def test_each_message_at_its_rate_on_schedule():
    fed = Fed()
    counts = {"vehicle/motion": 0, "vehicle/driver": 0}
    seqs: list[int] = []
    for i in range(200):                 # 1 s of polls every 5 ms, frames every 10 ms
        if i % 2 == 0:
            fed.all_signals()
        for key, msg in fed.poll():
            counts[key] += 1
            if key == "vehicle/motion":
                seqs.append(msg.header.seq)
        fed.advance(5)
    assert counts == {"vehicle/motion": 50, "vehicle/driver": 50}
    assert seqs == list(range(50))


def test_ticks_that_fall_behind_restart_the_schedule_instead_of_bursting():
    fed = Fed()
    fed.all_signals()
    assert len(fed.poll()) == 2
    fed.advance(50)                      # 2.5 periods without a tick
    fed.all_signals()
    assert len(fed.poll()) == 2          # one of each, not three
    fed.advance(10)
    assert fed.poll() == []              # the next one is a whole period later


def test_the_stamp_is_the_newest_value_of_the_message():
    fed = Fed()
    fed.all_signals()
    fed.advance(30)
    fed.send("VehicleSpeed", VehicleSpeed=10.0)
    newest = WALL0 + fed.mono
    fed.send("YawRate", YawRate=0.0)
    out = by_key(fed.poll())
    assert out["vehicle/motion"].header.stamp_ns == newest     # the gear is 30 ms older
    assert out["vehicle/driver"].header.stamp_ns == newest - 30 * MS


def test_a_message_is_withheld_while_any_of_its_signals_is_stale():
    fed = Fed()
    fed.all_signals()
    fed.poll()
    fed.advance(150)             # steering, pedals and brake outlive their 0.1 s
    fed.send("VehicleSpeed", VehicleSpeed=20.0)
    fed.send("YawRate", YawRate=1.0)
    out = by_key(fed.poll())
    assert set(out) == {"vehicle/motion"}          # the gear is fresh for 0.35 s
    assert fed.core.withheld.get("vehicle/driver") == 1
    reason = fed.core.not_ready_reason(BusState.ACTIVE, fed.mono)
    assert reason.startswith("stale: ") and "SteeringWheel.SteeringWheelAngle" in reason
    assert "VehicleSpeed" not in reason
    fed.advance(250)
    fed.send("VehicleSpeed", VehicleSpeed=20.0)
    fed.send("YawRate", YawRate=1.0)
    assert fed.poll() == []                        # now the gear is stale too
    assert fed.core.withheld.get("vehicle/motion") == 1
    health = {s.signal: s for s in fed.core.signals(fed.mono)}
    assert not health["Gear.GearLever"].fresh
    assert health["Gear.GearLever"].age_s == pytest.approx(0.4)
    assert health["VehicleSpeed.VehicleSpeed"].fresh


def test_readiness():
    fed = Fed()
    reason = fed.core.not_ready_reason(BusState.ACTIVE, fed.mono)
    assert reason.startswith("never received: VehicleSpeed.VehicleSpeed, YawRate.YawRate")
    fed.all_signals()
    assert fed.core.not_ready_reason(BusState.ACTIVE, fed.mono) == ""
    for state in (BusState.SILENT, BusState.ERROR, BusState.REOPENING, BusState.ENDED):
        assert fed.core.not_ready_reason(state, fed.mono) == BUS_NOT_READY[state]


def test_bad_frames_and_values_are_counted_and_the_last_good_value_kept():
    fed = Fed()
    fed.all_signals(kph=36.0)
    arb, data = frame("Brake", BrakePedalPressed=1, BrakePressure=20.0)
    fed.core.on_frame(arb, data[:-1], False, WALL0, fed.mono)       # one byte short
    fed.core.on_frame(0x5F0, b"\x01\x02", False, WALL0, fed.mono)   # not in the DBC
    fed.core.on_frame(arb, data, True, WALL0, fed.mono)             # the same ID, extended
    fed.send("Engine", EngineSpeed=2000.0)                          # nothing mapped in it
    fed.send("VehicleSpeed", VehicleSpeed=300.0)                    # 83 m/s > max 70
    fed.send("Gear", GearLever=7)                                   # "Invalid"
    assert fed.core.rejected.snapshot() == {"decode_error": 1, "out_of_range:speed_mps": 1,
                                            "unmapped_gear:7": 1}
    assert fed.core.ignored.snapshot() == {"not_in_dbc": 2, "no_mapped_signal": 1}
    out = by_key(fed.poll())
    assert out["vehicle/motion"].speed_mps == pytest.approx(10.0)   # the previous one
    assert out["vehicle/driver"].gear is Gear.DRIVE
    assert out["vehicle/driver"].brake_pedal_pressed is False


def test_random_payloads_of_every_message_never_raise():
    fed = Fed()
    rng = random.Random(7)
    for message in DB.messages:
        for _ in range(200):
            data = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 9)))
            fed.core.on_frame(message.frame_id, data, False, WALL0, fed.mono)
    total = (fed.core.frames_decoded + fed.core.rejected.total()
             + fed.core.ignored.get("no_mapped_signal"))
    assert total >= fed.core.frames_total == 200 * len(DB.messages)
    assert fed.core.rejected.get("decode_error") > 0


def test_frames_per_second_between_samples():
    fed = Fed()
    assert fed.core.frames_per_s(fed.mono) == 0.0
    for _ in range(100):
        fed.advance(5)
        fed.send("Pedals", AcceleratorPedal=1.0)
    assert fed.core.frames_per_s(fed.mono) == pytest.approx(200.0)
