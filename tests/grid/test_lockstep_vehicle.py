"""The vehicle's state in the lockstep loop: the ego's motion and the scenario's driver
reach fusion's core, the driver's override cases of tools/sim/families.py (each one AEB
would have braked in without the override, or leaves to the driver), and the degraded
mode when the loop publishes no vehicle state."""

from collections.abc import Iterator
from dataclasses import replace

import msgspec
import pytest

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.messages import Decision
from aeb_radar_camera.common.resources import DEPLOY, EXAMPLE_CALIBRATION
from aeb_radar_camera.tools.grid.camera import SceneCamera
from aeb_radar_camera.tools.grid.lockstep import LockstepResult, LoopConfig, run_scenario
from aeb_radar_camera.tools.sim.families import Case
from aeb_radar_camera.tools.sim.scenario import find_scenario, load_scenario
from aeb_radar_camera.tools.sim.scenario_run import LoopSettings

DEFAULT = LoopConfig.load(DEPLOY / "fusion.toml")


def without_override(config: LoopConfig) -> LoopConfig:
    f = config.fusion
    d = f.fusion.decision
    decision = msgspec.structs.replace(
        d, override=msgspec.structs.replace(d.override, enabled=False))
    fusion = msgspec.structs.replace(f, fusion=msgspec.structs.replace(f.fusion,
                                                                       decision=decision))
    return replace(config, fusion=fusion, name="no-override")


@pytest.fixture(scope="module")
def scenes() -> Iterator[SceneCamera]:
    yield SceneCamera(Calibration.load(EXAMPLE_CALIBRATION))


def run_case(family: str, kph: float, scenes: SceneCamera, config: LoopConfig = DEFAULT,
             **params: float) -> LockstepResult:
    return run_scenario(Case(family, kph, tuple(params.items())).scenario(), config, scenes)


def overrides(r: LockstepResult) -> set[str]:
    return {c.command.override for c in r.cycles} - {""}


def test_a_steering_override_suppresses_a_brake_aeb_would_otherwise_apply(scenes):
    r = run_case("override_steer", 60.0, scenes)
    assert r.verdict.passed and r.verdict.brake_activations == 0
    assert overrides(r) == {"steering"}
    assert all(c.targets.override == c.command.override for c in r.cycles)
    plain = run_case("override_steer", 60.0, scenes, without_override(DEFAULT))
    assert plain.verdict.brake_activations >= 1 and not plain.verdict.passed


def test_kickdown_is_seen_and_suppresses(scenes):
    r = run_case("override_kickdown", 50.0, scenes)
    assert r.verdict.passed and r.verdict.brake_activations == 0
    assert overrides(r) == {"kick-down"}


def test_the_drivers_braking_wins(scenes):
    r = run_case("override_brake", 50.0, scenes)
    assert r.verdict.passed and r.verdict.brake_activations == 0
    assert "brake pedal" in overrides(r)
    assert r.samples[-1].ego_speed_mps == 0.0          # the driver stopped the car


def test_fusion_sees_the_egos_speed_and_the_bend(scenes):
    r = run_case("bend_stopped_car", 30.0, scenes, radius_m=50.0)
    c = r.cycles[0]
    assert c.targets.ego_speed_mps == pytest.approx(30 / 3.6)
    assert c.targets.vehicle_state == ""
    assert any("R " in x.targets.path and "(yaw rate)" in x.targets.path for x in r.cycles)


def test_without_vehicle_state_the_kinematic_rule_only_warns(scenes):
    config = replace(DEFAULT, loop=LoopSettings(vehicle_motion=False), name="no-vehicle")
    r = run_scenario(load_scenario(find_scenario("stationary_car_30kph")), config, scenes)
    decisions = {c.command.decision for c in r.cycles}
    assert Decision.BRAKE not in decisions and Decision.WARNING in decisions
    assert all(c.targets.vehicle_state.startswith("vehicle/motion: nothing received")
               for c in r.cycles)
    assert r.verdict.collision
