"""`aeb demo` as a user runs it (two scenarios to keep the suite short): the stack starts,
the scenarios run in closed loop, a summary is printed and timeline plots are written."""

import json
import subprocess

import pytest

from tests.support import python_module

pytestmark = pytest.mark.slow

SCENARIOS = ["stationary_car_30kph", "no_threat_parked_cars_30kph"]


def test_demo_runs_scenarios_prints_a_summary_and_writes_plots(tmp_path):
    out = tmp_path / "demo"
    proc = subprocess.run(
        python_module("aeb_radar_camera.tools.cli", "demo", "--scenarios", ",".join(SCENARIOS),
                      "--out", str(out),
                      "--candidate"),
        capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-4000:] + \
        (out / "stack.log").read_text()[-4000:]
    text = proc.stdout
    assert "closed-loop SIMULATION" in text and "all services up" in text
    for name in SCENARIOS:
        line = next(ln for ln in text.splitlines() if ln.startswith(name))
        assert " PASS " in line
        png = out / f"{name}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "avoided (stopped)" in text and "no activation" in text
    assert "radar-to-brake latency" in text
    # The candidate ran in shadow mode: its outputs paired with the primary's per cycle.
    compared = next(ln for ln in text.splitlines() if ln.startswith("radar cycles compared"))
    assert int(compared.split()[3]) > 50, compared
    summary = json.loads((out / "summary.json").read_text())
    assert [s["scenario"] for s in summary["scenarios"]] == SCENARIOS
    assert summary["latency_ms"]["n"] > 50
    # Every service logged into the stack log, prefixed with its name.
    log = (out / "stack.log").read_text()
    for service in ("router", "radar", "camera", "fusion", "brake", "fusion-candidate"):
        assert f"\n{service}" in log or log.startswith(service)


def test_demo_lists_scenarios_and_rejects_unknown_ones():
    listed = subprocess.run(python_module("aeb_radar_camera.tools.cli", "demo", "--list"),
                            capture_output=True,
                            text=True, timeout=120)
    assert listed.returncode == 0
    assert "* stationary_car_30kph" in listed.stdout
    bad = subprocess.run(python_module("aeb_radar_camera.tools.cli", "demo", "--scenarios", "nope"),
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "no scenario 'nope'" in bad.stderr
