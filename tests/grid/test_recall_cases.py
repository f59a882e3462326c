"""The recall study's plan and tables: >= 200 held-out cases covering every obstacle kind,
size, pose and light; a regression is a threat the paper avoids and the default hits."""

from aeb_radar_camera.tools.grid.recall_cases import (
    PLAN,
    Row,
    generated,
    issue_rows,
    markdown,
    summarise,
)
from aeb_radar_camera.tools.messages import ObjectKind
from aeb_radar_camera.tools.sim.families import SPLITS


def test_the_plan_is_200_held_out_cases_over_every_kind_pose_and_light():
    cases = generated(PLAN)
    assert len(cases) >= 200
    assert all(c.seed in SPLITS["heldout"] for c in cases)
    assert len({c.name for c in cases}) == len(cases)
    scenarios = [c.scenario() for c in cases if c.family.startswith("obstacle")]
    kinds = {o.kind for sc in scenarios for o in sc.object}
    assert {ObjectKind.BOX, ObjectKind.PEDESTRIAN, ObjectKind.BICYCLE, ObjectKind.CAR} <= kinds
    params = [dict(c.params) for c in cases if c.family == "obstacle_standing"]
    assert {p["pose"] for p in params} == {"facing", "side-on"}
    assert {p["light"] for p in params} == {"day", "dusk"}
    assert min(float(p["size_m"]) for p in params) == 0.4
    assert {c.speed_kph for c in cases if c.family.startswith("obstacle")} == {10, 20, 30}
    false = {c.family for c in cases if c.family in ("plate", "overhead_sign", "ghost")}
    assert false == {"plate", "overhead_sign", "ghost"}


def test_the_issue_rows_are_ten_runs_each_on_held_out_or_loop_seeds():
    rows = issue_rows(10)
    names = {r for r, _, _ in rows}
    assert len(names) == 4 and len(rows) == 40
    shipped = [seed for r, sc, seed in rows if sc.name == "bicycle_crossing_20kph"]
    assert shipped == list(range(10))


def row(case, config, threat, avoided, activations=0, impact=None):
    return Row("fam", case, 20.0, config, threat, avoided, impact, activations, 0)


def test_regressions_are_threats_the_paper_avoids_and_the_default_hits():
    rows = [row("a_20kph", "default", True, True), row("a_20kph", "paper", True, True),
            row("b_20kph", "default", True, False, impact=18.0),
            row("b_20kph", "paper", True, True),
            row("c_30kph", "default", True, False, impact=30.0),
            row("c_30kph", "paper", True, False, impact=30.0)]
    s = summarise(rows)
    assert s["regressions"] == ["b_20kph"]
    assert s["misses"]["default"] == ["b_20kph", "c_30kph"]
    fam = s["families"]["fam"]
    assert fam["default"]["avoided"] == 1 and fam["default"]["mean_impact_kph"] == 24.0
    assert "1/3 avoided" in markdown(s, ["default", "paper"])


def test_false_targets_count_cases_with_an_activation():
    rows = [row("g_30kph", "default", False, True), row("g_30kph", "paper", False, True, 2)]
    s = summarise(rows)
    assert s["false_activations"] == {"default": [], "paper": ["g_30kph"]}
    assert "1/1 activated" in markdown(s, ["default", "paper"])
