"""The sample drive (SIMULATED): a scripted 13 s drive of a generic car, every chassis
message of the sample DBC encoded at its cycle time with cantools' encoder, written as a
candump log. It is the vehicle gateway's sample input (deploy/recordings/vehicle/), and
a test checks that the shipped file is exactly what this script writes:

    python -m tests.vehicle.drive --write

The drive: parked with the brake held, drive engaged, away at 2 m/s^2, a kick-down,
a left bend at 33 km/h (steering wheel to +60 deg), braking at 5 m/s^2 to a stop,
reverse engaged, backing away. A few frames are wrong on purpose, as on a real bus:
one truncated Brake frame, one GearLever "Invalid" code, and a message the DBC does not
know (another ECU's), ten times a second.
"""

import argparse
import math
import random
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cantools

from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.services.vehicle.dbc import load_dbc

DBC = DEPLOY / "vehicle" / "generic-car.dbc"
LOG = DEPLOY / "recordings" / "vehicle" / "candump-generic-car-drive.log"
CHANNEL = "can0"
START_S = 1_767_225_600.0          # 2026-01-01 00:00:00 UTC: any fixed time
DURATION_S = 13.0
WHEELBASE_M = 2.7
STEERING_RATIO = 15.0
TRACK_M = 1.6
GEAR_CODE = {"P": 0, "R": 1, "N": 2, "D": 3}
# message -> (period s, phase s): the DBC's cycle times, each message at its own phase
SCHEDULE = {"WheelSpeeds": (0.02, 0.000), "VehicleSpeed": (0.02, 0.001),
            "YawRate": (0.02, 0.003), "SteeringWheel": (0.01, 0.005),
            "Pedals": (0.02, 0.007), "Brake": (0.02, 0.009), "Gear": (0.1, 0.011),
            "Engine": (0.05, 0.013)}
FOREIGN_ID = 0x5F0                  # a message the DBC does not have
TRUNCATED_BRAKE_AT_S = 5.009        # this Brake frame loses its last byte
INVALID_GEAR_AT_S = 3.011           # this Gear frame says 7 ("Invalid")


@dataclass(frozen=True)
class DriveState:
    speed_mps: float            # magnitude; the direction is the gear's
    accel_mps2: float           # along the direction of travel
    steering_deg: float         # steering wheel, left positive
    steering_rate_dps: float
    pedal_pct: float
    kickdown: bool
    brake_bar: float            # 0: pedal released
    gear: str


# (until s, acceleration, pedal %, kick-down, brake bar, gear): the drive, piece by piece
_PIECES = ((1.0, 0.0, 0.0, False, 12.0, "P"), (1.5, 0.0, 0.0, False, 12.0, "D"),
           (4.0, 2.0, 35.0, False, 0.0, "D"), (4.6, 3.5, 100.0, True, 0.0, "D"),
           (6.0, 1.5, 40.0, False, 0.0, "D"), (9.0, 0.0, 20.0, False, 0.0, "D"),
           (9.2, -0.2, 0.0, False, 0.0, "D"), (11.3, -5.0, 0.0, False, 35.0, "D"),
           (11.5, 0.0, 0.0, False, 15.0, "N"), (11.7, 0.0, 0.0, False, 15.0, "R"),
           (DURATION_S + 1, 1.0, 10.0, False, 0.0, "R"))


def _piece(t: float) -> tuple[float, float, float, bool, float, str]:
    return next(p for p in _PIECES if t < p[0])


def steering_deg(t: float) -> float:
    """The bend: up to +60 deg over 6.0-6.8 s, held, back to 0 over 8.2-9.0 s."""
    if t < 6.0 or t >= 9.0:
        return 0.0
    if t < 6.8:
        return 60.0 * (1 - math.cos(math.pi * (t - 6.0) / 0.8)) / 2
    if t < 8.2:
        return 60.0
    return 60.0 * (1 + math.cos(math.pi * (t - 8.2) / 0.8)) / 2


STEP_S = 0.001


def states() -> Iterator[DriveState]:
    """The drive every millisecond from 0 to DURATION_S (speed integrated)."""
    speed = 0.0
    step_s = STEP_S
    for i in range(round(DURATION_S / step_s) + 1):
        t = i * step_s
        _, accel, pedal, kick, brake, gear = _piece(t)
        speed = max(0.0, speed + accel * step_s)
        moving = accel if speed > 0 or accel > 0 else 0.0
        rate = (steering_deg(t + step_s) - steering_deg(t)) / step_s
        yield DriveState(speed, moving, steering_deg(t), rate, pedal, kick, brake, gear)


def yaw_rate_dps(s: DriveState) -> float:
    """Kinematic bicycle: v tan(wheel angle) / wheelbase, backwards negative."""
    wheel = math.radians(s.steering_deg / STEERING_RATIO)
    sign = -1.0 if s.gear == "R" else 1.0
    return math.degrees(sign * s.speed_mps * math.tan(wheel) / WHEELBASE_M)


def signals(name: str, s: DriveState, counter: int, rng: random.Random) -> dict[str, float]:
    """The physical values of message `name` in drive state `s`."""
    kph = s.speed_mps * 3.6
    yaw = yaw_rate_dps(s)
    half_track = math.radians(yaw) * TRACK_M / 2 * 3.6
    if name == "WheelSpeeds":
        left, right = max(0.0, kph - half_track), max(0.0, kph + half_track)
        return {"WheelSpeed_FL": left, "WheelSpeed_FR": right,
                "WheelSpeed_RL": left, "WheelSpeed_RR": right}
    if name == "VehicleSpeed":
        return {"VehicleSpeed": kph, "StandStill": int(s.speed_mps < 0.01),
                "VehicleSpeed_Counter": counter % 16}
    if name == "YawRate":
        return {"YawRate": yaw + rng.gauss(0.0, 0.05),
                "LateralAccel": s.speed_mps * math.radians(yaw),
                "LongitudinalAccel": s.accel_mps2}
    if name == "SteeringWheel":
        return {"SteeringWheelAngle": s.steering_deg, "SteeringWheelRate": s.steering_rate_dps}
    if name == "Pedals":
        return {"AcceleratorPedal": s.pedal_pct, "Kickdown": int(s.kickdown)}
    if name == "Brake":
        return {"BrakePedalPressed": int(s.brake_bar > 0), "BrakePressure": s.brake_bar}
    if name == "Gear":
        return {"GearLever": GEAR_CODE[s.gear]}
    return {"EngineSpeed": 800.0 + 90.0 * kph, "CoolantTemp": 90.0}


def candump_lines(db: cantools.database.can.Database) -> list[str]:
    """The drive as candump -l lines, in time order."""
    rng = random.Random(27)
    drive = list(states())
    frames: list[tuple[float, int, bytes]] = []
    for name, (period, phase) in SCHEDULE.items():
        message = db.get_message_by_name(name)
        k = 0
        while (t := phase + k * period) < DURATION_S:
            state = drive[round(t / STEP_S)]
            values = signals(name, state, k, rng)
            at = t + rng.uniform(-0.0003, 0.0003)
            if name == "Gear" and abs(t - INVALID_GEAR_AT_S) < 1e-9:
                values = {"GearLever": 7}
            data = message.encode(values)
            if name == "Brake" and abs(t - TRUNCATED_BRAKE_AT_S) < 1e-9:
                data = data[:-1]
            frames.append((at, message.frame_id, data))
            k += 1
    frames += [(0.015 + 0.1 * k, FOREIGN_ID, bytes([k % 256, 0x5A]))
               for k in range(int(DURATION_S / 0.1))]
    frames.sort()
    return [f"({START_S + t:.6f}) {CHANNEL} {arb:03X}#{data.hex().upper()}\n"
            for t, arb, data in frames]


def render() -> str:
    return "".join(candump_lines(load_dbc(str(DBC))))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tests.vehicle.drive",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--write", action="store_true", help=f"write {LOG}")
    args = parser.parse_args(argv)
    text = render()
    if args.write:
        LOG.parent.mkdir(parents=True, exist_ok=True)
        Path(LOG).write_text(text)
        print(f"wrote {LOG} ({text.count(chr(10))} frames)")
        return 0
    same = LOG.is_file() and LOG.read_text() == text
    print(f"{LOG}: {'up to date' if same else 'differs from the script (--write)'}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
