"""`aeb grid`: the quick set (one case per family) as a user runs it, in its own process,
with its table, JSON, heat maps, timeline plots and progress; a candidate in shadow mode
reported where it decided differently; bad arguments and configurations exit 2."""

import json
import subprocess
import sys

import pytest

from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.tools.grid.main import main, parse_seeds, pick_cases, pick_families
from aeb_radar_camera.tools.sim.families import FAMILIES
from tests.support import REPO

pytestmark = pytest.mark.slow


def test_quick_grid_in_its_own_process(tmp_path):
    out = tmp_path / "grid"
    r = subprocess.run([sys.executable, "-m", "aeb_radar_camera.tools.cli", "grid", "--quick",
                        "--workers", "2",
                        "--out", str(out)], capture_output=True, text=True, timeout=240,
                       cwd=REPO)
    assert r.returncode == 0, r.stderr[-3000:]
    n = len(FAMILIES)
    assert f"[{n}/{n}]" in r.stderr                      # progress, a line per case
    report = json.loads((out / "grid.json").read_text())
    cases = report["cases"]
    assert sorted(c["family"] for c in cases) == sorted(FAMILIES)
    assert all(not c["error"] for c in cases)
    assert {f["family"] for f in report["families"]} == set(FAMILIES)
    md = (out / "grid.md").read_text()
    for family in FAMILIES:
        assert f"| {family} |" in md
        assert (out / "fusion" / "heatmaps" / f"{family}.png").stat().st_size > 1000
    for c in cases:
        assert (out / "fusion" / "plots" / c["family"] / f"{c['name']}.png").is_file()
    # the paper's speed: the stationary car ahead is avoided, a plate is no reason to brake
    by = {c["family"]: c for c in cases}
    assert by["CCRs"]["speed_kph"] == 30.0 and by["CCRs"]["outcome"].startswith("avoided")
    assert by["CCRs"]["first_brake_t_s"] is not None and by["CCRs"]["points"] == 1.0
    assert by["plate"]["false_activations"] == 0
    assert report["floors"]["fusion"]["confirm_cycles"] == 3


def test_a_candidate_is_reported_where_it_decided_differently(tmp_path, capsys):
    # The paper's gate brakes for a plate in the lane; the default does not.
    code = main(["--families", "plate", "--speeds", "30", "--candidate",
                 str(DEPLOY / "fusion-paper.toml"), "--no-plots", "--workers", "1",
                 "--out", str(tmp_path)])
    assert code == 0
    report = json.loads((tmp_path / "grid.json").read_text())
    assert len(report["cases"]) == 3
    differing = [c for c in report["cases"] if c["shadow"]["differing"]]
    assert differing, "the paper's gate braked for no plate"
    assert all(c["shadow"]["candidate_brake_t_s"] is not None for c in differing)
    assert all(c["false_activations"] == 0 for c in report["cases"])   # followed: no brake
    md = (tmp_path / "grid.md").read_text()
    assert "decided differently (shadow mode)" in md and differing[0]["name"] in md
    assert not list(tmp_path.glob("*/plots"))


@pytest.mark.parametrize("argv", [["--families", "CCRx"], ["--seeds", "bogus:3"],
                                  ["--speeds", "fast"], ["--workers", "0"],
                                  ["--config", "/nonexistent/fusion.toml"],
                                  ["--speeds", "70"]])
def test_bad_arguments_exit_2_with_a_message(argv, tmp_path, capsys):
    assert main([*argv, "--out", str(tmp_path)]) == 2
    assert "error:" in capsys.readouterr().err
    assert not (tmp_path / "grid.json").exists()


def test_seeds_groups_and_the_quick_set():
    assert parse_seeds("0,heldout:2") == [0, 2000, 2001]
    assert parse_seeds("nominal,0") == [0]
    assert pick_families("CCRb,bend") == ["CCRb", "bend_stopped_car"]
    quick = pick_cases(list(FAMILIES), [], [0], quick=True)
    assert len(quick) == len(FAMILIES)
    assert {c.speed_kph for c in quick if c.family == "CCRb"} == {50.0}   # its only speed
    assert all(c.speed_kph == 30.0 for c in quick if c.family == "CCRs")
    full = pick_cases(["CCRs"], [40.0], [0, 2000], quick=False)
    assert len(full) == 5 * 2 and {c.speed_kph for c in full} == {40.0}
