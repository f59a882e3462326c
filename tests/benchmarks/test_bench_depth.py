"""The depth benchmark runs, writes its files and measures what it says."""

import json

from benchmarks import bench_depth
from benchmarks.suite import SECTIONS


def test_quick_run_writes_figures_beside_their_baselines(tmp_path):
    figures = bench_depth.run(True, tmp_path)
    assert SECTIONS["depth"] == "benchmarks.bench_depth"
    names = {f.name for f in figures}
    assert "depth verifier per ROI, mean" in names
    assert all(f.baseline_value and f.baseline_value > 0 for f in figures)
    result = json.loads((tmp_path / "bench_depth.json").read_text())
    enc = result["encodings"]
    # Both codecs are lossless on the same pixels; decimation 2 quarters the raw bytes.
    assert {r["codec"] for r in enc.values() if "codec" in r} == {"zstd", "png"}
    full, half = enc["zstd 848x480 D435 noise"], enc["zstd 424x240 D435 noise"]
    assert full["raw_bytes"] == 4 * half["raw_bytes"] == 848 * 480 * 2
    assert 0 < half["bytes_mean"] < full["bytes_mean"] < full["raw_bytes"]
    assert result["verifiers"]["verified"]["road"]["passed"] == 0
    assert (tmp_path / "bench_depth.png").stat().st_size > 0
