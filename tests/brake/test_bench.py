"""The brake benchmark still runs end to end (a short run; figures are not asserted)."""

import json

import pytest

from benchmarks import bench_brake

pytestmark = pytest.mark.slow


def test_benchmark_runs_and_writes_its_table_plot_and_json(tmp_path, capsys):
    assert bench_brake.main(["--count", "60", "--rate-hz", "100", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "command receipt -> serial write" in out and "baseline" in out
    assert (tmp_path / "bench_brake.png").stat().st_size > 0
    rows = json.loads((tmp_path / "bench_brake.json").read_text())["rows"]
    assert all(r["n"] > 0 for r in rows.values())


def test_the_validation_benchmark_accepts_every_command_and_prints_its_rows(capsys):
    from benchmarks.bench_brake_validate import main

    assert main(["--count", "300"]) == 0
    out = capsys.readouterr().out
    for row in ("baseline: decode", "MAC check", "validate (whole check)"):
        assert row in out
