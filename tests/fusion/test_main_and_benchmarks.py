"""`aeb fusion` fails fast on bad configuration; the benchmarks run (--quick)."""

import json
import subprocess
import sys

import pytest

from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import load_config
from aeb_radar_camera.services.fusion.main import build_core
from benchmarks import bench_fusion, bench_gate


@pytest.mark.parametrize(("toml", "named"), [
    ("[fusion.verifier]\nname = 'sobel'\n", "unknown verifier 'sobel'"),
    ("[fusion.verifier]\nparams = { tau = 2.0 }\n", "tau"),
    ("[fusion]\ncalibration = 'nope.toml'\n", "nope.toml"),
    ("[fusion.decision]\nhold_s = -1.0\n", "$.fusion.decision.hold_s"),
    ("[fusion]\ninstance = 'a/b'\n", "instance"),
])
def test_bad_configuration_exits_2_naming_the_problem(tmp_path, toml, named):
    cfg = tmp_path / "fusion.toml"
    cfg.write_text(toml)
    proc = subprocess.run([sys.executable, "-m", "aeb_radar_camera.services.fusion", "-c",
                           str(cfg)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert named in proc.stderr


def test_another_instances_key_exits_2_naming_both_instances():
    proc = subprocess.run([sys.executable, "-m", "aeb_radar_camera.services.fusion", "-c",
                           "deploy/fusion.toml",
                           "--instance", "shadow", "--check"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert "primary.key: key of instance 'primary', this is 'shadow'" in proc.stderr


@pytest.mark.parametrize("path", ["deploy/fusion.toml", "deploy/fusion-candidate.toml",
                                  "deploy/fusion-paper.toml"])
def test_shipped_configs_build(path):
    core, _ = build_core(load_config(path, FusionConfig))
    assert core.source == f"fusion/{core.s.instance}"


def test_paper_profile_turns_every_addition_off():
    s = load_config("deploy/fusion-paper.toml", FusionConfig).fusion
    d = s.decision
    assert not d.corridor.enabled and d.hold_s == 0 and not s.frames.align
    assert d.unverifiable_policy.value == "ignore" and s.gate_scope.value == "all"
    assert (s.verifier.name, s.verifier.params) == (
        "edge_density", {"low": 40, "high": 120, "tau": 0.025})
    assert (d.min_range_m, d.max_range_m, d.ttc_offset_s, d.brake_ttc_eff_s) == (
        3.0, 25.0, 1.0, 2.5)
    assert (s.roi.column_height_m, s.roi.padding_px, s.roi.column_half_width_m) == (2.2, 22, 0)


@pytest.mark.slow
def test_benchmarks_run_quick_and_write_their_results(tmp_path, capsys):
    assert bench_gate.main(["--quick", "--out", str(tmp_path)]) == 0
    gate = json.loads((tmp_path / "bench_gate.json").read_text())
    assert gate["densities"]["identical_densities"] is True
    assert (tmp_path / "bench_gate.png").stat().st_size > 0
    figures = bench_fusion.run(True, tmp_path)
    fusion = json.loads((tmp_path / "bench_fusion.json").read_text())
    assert fusion["gate all 64"]["gated_mean"] == 64
    assert fusion["threats 64"]["gated_mean"] == 64          # every threat, for the targets
    assert fusion["threats 64"]["gated_first_mean"] < 64     # the command needed fewer
    assert (tmp_path / "bench_fusion.png").stat().st_size > 0
    assert (tmp_path / "bench_fusion_cameras.png").stat().st_size > 0
    assert "64 tracks, threats" in capsys.readouterr().out
    # The cameras scale (quick: its two ends): every camera count streamed into fusion,
    # its frames decoded.
    cams = fusion["cameras"]
    assert cams["counts"] == list(bench_fusion.QUICK_CAMERA_COUNTS) == [1, 4]
    for n in (1, 4):
        assert cams[f"{n} traffic"]["frames_decoded_per_s"] > 10 * n
    names = {f.name for f in figures}
    assert {f"fusion tracks->command, {n} tracks (threats)" for n in (1, 8, 64, 128)} <= names
    assert {f"decode CPU, {n} camera(s) at 30 fps" for n in (1, 4)} <= names
    assert all(f.group == "scale" and f.baseline_value is not None for f in figures)


def test_the_gate_benchmark_refuses_to_compare_different_densities(tmp_path, monkeypatch):
    monkeypatch.setattr(bench_gate, "naive_density", lambda bgr, roi: -1.0)
    with pytest.raises(RuntimeError, match="densities differ"):
        bench_gate.run(True, tmp_path)
    assert bench_gate.main(["--quick", "--out", str(tmp_path)]) == 1


def test_the_gate_benchmark_reports_its_figures(tmp_path):
    figures = bench_gate.run(True, tmp_path)
    names = [f.name for f in figures]
    assert "edge_density mean, roi 4.3% (134x130)" in names
    assert "edge_density p95, full frame (848x480)" in names
    assert any(n.startswith("full frame / roi 1.3%") for n in names)
    same = next(f for f in figures if f.name.startswith("ROIs with densities identical"))
    assert same.target_met is True and same.value == same.baseline_value
    assert all(f.group == "gate" and f.baseline_value is not None for f in figures)


def test_the_verifier_benchmark_times_every_verifier_beside_the_papers_gate(tmp_path, capsys):
    from benchmarks import bench_verifiers

    figures = bench_verifiers.run(True, tmp_path)
    result = json.loads((tmp_path / "bench_verifiers.json").read_text())
    timing = result["timing"]
    assert {"edge_density", "depth", "hog_people", "hog_linear",
            "combined (depth + hog_linear)"} <= set(timing)
    assert all(t["n"] > 0 and t["p50_us"] > 0 for t in timing.values())
    assert result["rois"] > 0 and (tmp_path / "bench_verifiers.png").stat().st_size > 0
    assert {f.baseline_value for f in figures} == {timing["edge_density"]["mean_us"]}
    assert "x edge_density" in capsys.readouterr().out
