"""The simulator's benchmark runs and measures every condition it names."""

from benchmarks import bench_sim
from benchmarks.suite import SECTIONS


def test_quick_run_measures_every_frame_kind_and_the_world_beside_baselines(tmp_path):
    figures = bench_sim.run(True, tmp_path)
    assert SECTIONS["sim"] == "benchmarks.bench_sim"
    names = {f.name for f in figures}
    for kind in ("day", "day with depth", "dusk", "night", "rain", "bend, in it",
                 "bend, approaching at 20 km/h", "bend, approaching at 60 km/h"):
        assert f"frame, {kind}" in names
    assert any(n.startswith("tick (step + ground truth), guard rail") for n in names)
    assert all(f.value > 0 and f.baseline_value and f.baseline_value > 0 for f in figures)
