"""Many lockstep runs in worker processes: the same outcomes as in the caller's process,
in the order given, with progress, and a case that cannot run reported beside the
others."""

import threading

import pytest

from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.tools.grid.pool import Case, Outcome, run_cases
from aeb_radar_camera.tools.sim.scenario import find_scenario, load_scenario

pytestmark = pytest.mark.slow

NAMES = ("pedestrian_standing_20kph", "no_threat_manhole_30kph", "cardboard_box_30kph")


def test_workers_give_the_outcomes_of_one_process_in_order_with_progress(tmp_path):
    cases = [Case(load_scenario(find_scenario(n)), DEPLOY / "fusion.toml") for n in NAMES]
    cases.insert(1, Case(cases[0].scenario, tmp_path / "missing.toml", name="broken"))
    seen: list[tuple[int, int, str]] = []

    def progress(done: int, total: int, o: Outcome) -> None:
        seen.append((done, total, o.case.label))

    pooled = run_cases(cases, workers=2, progress=progress)
    assert [o.case.label for o in pooled] == [NAMES[0], "broken", *NAMES[1:]]
    assert [(done, total) for done, total, _ in seen] == [(1, 4), (2, 4), (3, 4), (4, 4)]
    assert {label for _, _, label in seen} == {*NAMES, "broken"}
    broken = pooled[1]
    assert broken.result is None and "missing.toml" in broken.error and broken.detail
    alone = run_cases([cases[0], cases[2]], workers=1)
    for mine, theirs in zip(alone, (pooled[0], pooled[2]), strict=True):
        assert mine.result is not None and theirs.result is not None
        assert mine.result.samples == theirs.result.samples
        assert mine.result.verdict == theirs.result.verdict
    assert [o.result.verdict.passed for o in pooled if o.result is not None] == [True] * 3


def test_once_stopped_no_case_starts_and_those_running_finish():
    case = Case(load_scenario(find_scenario("no_threat_parked_cars_30kph")),
                DEPLOY / "fusion.toml")
    stop = threading.Event()

    def progress(done: int, total: int, o: Outcome) -> None:
        stop.set()

    outcomes = run_cases([case] * 8, workers=2, progress=progress, stop=stop)
    assert 1 <= len(outcomes) < 8
    assert all(o.result is not None and o.result.verdict.passed for o in outcomes)
