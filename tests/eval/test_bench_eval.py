"""The evaluation benchmark in its short mode: its recording has the paper's ROIs per
frame and its figures carry their baselines and the 10-minute target."""

import json

from benchmarks import bench_eval
from benchmarks.suite import SECTIONS


def test_quick_benchmark_reports_rois_per_core_and_the_projection(tmp_path):
    figures = bench_eval.run(True, tmp_path)
    result = json.loads((tmp_path / "bench_eval.json").read_text())
    assert abs(result["rois_per_frame"] - bench_eval.PAPER_ROIS / bench_eval.PAPER_FRAMES) < 0.02
    assert result["decoded_baseline"] == result["cycles"]
    names = {f.name: f for f in figures}
    per_core = names["ROIs/s per core"]
    assert per_core.value > 0 and per_core.baseline_value is not None
    projected = names[f"paper's {bench_eval.PAPER_FRAMES:,} frames on 2 cores, projected"]
    assert projected.target == "< 10 min" and projected.target_met == (projected.value < 10)
    assert projected.baseline_value is not None and projected.baseline_value < projected.value
    assert SECTIONS["eval"] == "benchmarks.bench_eval"
