"""Fusion as its own process with the kinematic rule, reading `vehicle/motion` and
`vehicle/driver` from the bus: braking while the state is fresh, the degraded mode (at
most WARNING, the reason in the messages, `vehicle_state_stale` counted and logged) once
the publisher stops, and back to braking when it resumes."""

import threading
from pathlib import Path

import pytest

from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.keys import (
    EGO_MOTION,
    FUSION_BRAKE_CMD,
    FUSION_TARGETS,
    VEHICLE_DRIVER,
)
from aeb_radar_camera.common.messages import Decision, DriverInputs, EgoMotion, Gear, Header
from tests.fusion.helpers import CALIBRATION, track
from tests.fusion.test_fusion_processes import Radar
from tests.support import Collector, HealthWatch, ServiceProcess, open_bus, python_module, wait_for

pytestmark = pytest.mark.slow

INSTANCE = "kin"
SPEED = 20 / 3.6


def write_config(tmp: Path, endpoint: str) -> Path:
    cfg = tmp / "fusion.toml"
    # No camera runs: the camera check is unavailable, and radar_only lets the threat
    # through, so that the vehicle state is the only thing between the track and BRAKE.
    cfg.write_text(f"""
[zenoh]
connect = ["{endpoint}"]
[fusion]
instance = "{INSTANCE}"
calibration = "{CALIBRATION}"
stats_interval_s = 0.5
[fusion.decision]
rule = "kinematic"
unverifiable_policy = "radar_only"
hold_s = 0.0
radar_max_age_s = 1.0
[fusion.vehicle_state]
max_age_s = 0.1
""")
    return cfg


class Gateway:
    """Plays the vehicle gateway at 50 Hz from a thread while `running` is set."""

    def __init__(self, bus) -> None:
        self.motion = bus.publisher(EGO_MOTION)
        self.driver = bus.publisher(VEHICLE_DRIVER)
        self.running = threading.Event()
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        seq = 0
        while not self.stop.wait(0.02):
            if not self.running.is_set():
                continue
            header = Header(seq=seq, source="test", stamp_ns=wall_ns(), pub_mono_ns=mono_ns())
            seq += 1
            self.motion.put(EgoMotion(header=header, speed_mps=SPEED, yaw_rate_dps=0.0))
            self.driver.put(DriverInputs(
                header=header, steering_wheel_angle_deg=0.0, steering_wheel_rate_dps=0.0,
                accelerator_pedal_pct=20.0, kickdown=False, brake_pedal_pressed=False,
                brake_pressure_bar=0.0, gear=Gear.DRIVE))


def test_fusion_process_brakes_on_fresh_vehicle_state_and_warns_only_when_it_stops(
        router, tmp_path):
    cfg = write_config(tmp_path, router)
    threat = track(1, 8.0, 0.0, vx=-SPEED)            # TTC 1.44 s: full brake
    with open_bus(router) as bus:
        watch = HealthWatch(bus)
        commands, targets = Collector(), Collector()
        bus.subscribe(FUSION_BRAKE_CMD, commands, instance=INSTANCE)
        bus.subscribe(FUSION_TARGETS, targets, instance=INSTANCE)
        gateway = Gateway(bus)
        gateway.thread.start()
        fusion = ServiceProcess("fusion", python_module("aeb_radar_camera.services.fusion", "-c",
                                                        str(cfg)),
                                tmp_path)
        try:
            watch.wait_alive("fusion", INSTANCE)
            radar = Radar(bus, commands, targets)

            # Nothing received yet: missing, at most WARNING.
            cmd, tgt = radar.cycle(threat)
            assert cmd.decision is Decision.WARNING
            assert "vehicle/motion: nothing received" in tgt.vehicle_state

            gateway.running.set()
            wait_for(lambda: radar.cycle(threat)[0].decision is Decision.BRAKE, 30,
                     interval_s=0.05, what="BRAKE on fresh vehicle state")
            cmd, tgt = radar.cycle(threat)
            assert cmd.brake_level_pct == 100.0 and tgt.vehicle_state == ""
            assert tgt.ego_speed_mps == pytest.approx(SPEED)

            # The gateway goes quiet: stale after the bound, WARNING with the reason.
            gateway.running.clear()
            wait_for(lambda: radar.cycle(threat)[0].decision is Decision.WARNING, 30,
                     interval_s=0.05, what="degraded after the state went stale")
            cmd, tgt = radar.cycle(threat)
            assert "vehicle/motion: newest is" in tgt.vehicle_state
            assert "at most WARNING" in cmd.reason and cmd.brake_level_pct == 0.0
            wait_for(lambda: "vehicle_state_stale" in fusion.output(), 30,
                     what="the degraded mode logged and counted")

            # Back: braking again.
            gateway.running.set()
            wait_for(lambda: radar.cycle(threat)[0].decision is Decision.BRAKE, 30,
                     interval_s=0.05, what="BRAKE again once fresh")
        finally:
            gateway.stop.set()
            fusion.stop()
    # The last statistics, logged on the way out: the counter and the inputs' own counts.
    stats = [line for line in fusion.log_path.read_text(errors="replace").splitlines()
             if "fusion_stats" in line]
    assert stats and "vehicle_state_stale=" in stats[-1]
    assert "vehicle_motion_went_stale=1" in stats[-1]
    assert "vehicle_motion_accepted=" in stats[-1]
