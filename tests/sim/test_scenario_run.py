"""A scenario run tick by tick, as the real-time runner and the lockstep loop both drive
it: the radar's schedule, the samples, when a run ends, `sim/world`."""

import random
from itertools import pairwise

from aeb_radar_camera.common.messages import Header
from aeb_radar_camera.tools.messages import ObjectKind
from aeb_radar_camera.tools.sim.scenario import EgoSpec, Scenario, ScenarioKind, SceneObject
from aeb_radar_camera.tools.sim.scenario_run import (
    LoopSettings,
    RadarSchedule,
    ScenarioRun,
    radar_view,
    world_message,
)

TICK = 0.005
SETTINGS = LoopSettings()
HEADER = Header(seq=0, source="sim", stamp_ns=0, pub_mono_ns=0)


def scenario(kind: ScenarioKind, x_m: float, y_m: float = 0.0, duration_s: float = 20.0,
             ) -> Scenario:
    return Scenario(name="t", kind=kind, ego=EgoSpec(speed_kph=20.0), duration_s=duration_s,
                    object=(SceneObject(ObjectKind.BOX, x_m, y_m),))


def play(run: ScenarioRun, position_pct: float = 0.0, limit_s: float = 30.0) -> None:
    while not run.ended and run.world.t_s < limit_s:
        run.step(TICK, position_pct)
        run.record("NONE", "ARMED", position_pct, position_pct, SETTINGS)


def test_radar_cycles_fall_every_72_to_76_ms_and_a_late_loop_sends_one_not_a_burst():
    schedule = RadarSchedule((0.072, 0.076), random.Random(1), 0.0)
    due = [k * TICK for k in range(2000) if schedule.due(k * TICK)]
    gaps = [b - a for a, b in pairwise(due)]
    # at the first tick on or after each due time, on average every 74 ms
    assert min(gaps) >= 0.072 - TICK and max(gaps) <= 0.076 + TICK
    assert abs((due[-1] - due[0]) / len(gaps) - 0.074) < 0.001
    assert schedule.late == 0
    assert schedule.due(100.0) and not schedule.due(100.0) and schedule.late == 1
    assert not schedule.due(100.0 + 0.071) and schedule.due(100.0 + 0.072)


def test_a_threat_run_ends_at_the_collision_with_a_sample_per_tick():
    run = ScenarioRun.start(scenario(ScenarioKind.THREAT, 10.0), 1)
    play(run)
    assert run.ended and run.world.collision is not None
    assert len(run.samples) == round(run.world.t_s / TICK)
    assert run.samples[0].gap_m is not None and run.samples[0].decision == "NONE"
    assert run.verdict().collision and not run.verdict().passed


def test_a_run_ends_after_the_ego_stood_still_for_the_hold():
    run = ScenarioRun.start(scenario(ScenarioKind.THREAT, 30.0), 1)
    play(run, position_pct=100.0)
    stopped = next(s.t_s for s in run.samples if s.ego_speed_mps <= 0.01)
    assert run.ended and run.world.collision is None
    assert abs(run.samples[-1].t_s - stopped - SETTINGS.stopped_hold_s) < 2 * TICK
    assert run.verdict().outcome == "avoided (stopped)"


def test_a_no_threat_run_ends_past_every_object_and_any_run_at_its_duration():
    beside = ScenarioRun.start(scenario(ScenarioKind.NO_THREAT, 10.0, y_m=4.0), 1)
    play(beside)
    assert beside.ended and beside.world.passed_everything(SETTINGS.passed_margin_m)
    short = ScenarioRun.start(scenario(ScenarioKind.THREAT, 50.0, duration_s=1.0), 1)
    play(short)
    assert short.ended and abs(short.world.t_s - 1.0) < 2 * TICK


def test_the_radar_and_the_camera_see_the_empty_road_between_runs():
    assert radar_view(None) == ([], 0.0, 0.0, 0.0)
    idle = world_message(None, HEADER, 3)
    assert (idle.active, idle.run, idle.objects, idle.ego_speed_mps) == (False, 3, (), 0.0)
    run = ScenarioRun.start(scenario(ScenarioKind.THREAT, 10.0), 4)
    bodies, ego_x, speed, yaw_rate = radar_view(run)
    assert len(bodies) == 1 and ego_x == 0.0 and speed > 5.0 and yaw_rate == 0.0
    live = world_message(run, HEADER, 4)
    assert live.active and live.run == 4 and live.gap_m is not None and len(live.objects) == 1
    play(run)
    assert radar_view(run) == ([], 0.0, 0.0, 0.0) and not world_message(run, HEADER, 4).active
