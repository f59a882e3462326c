"""The radar benchmark's figures for the suite: every mode against the 2 ms target beside
the scalar decode of the same frames measured in the same run, and the cluster scale (timings are
printed by `python -m benchmarks.bench_radar`, never asserted)."""

from benchmarks.bench_radar import (
    BASELINE,
    CLUSTER_COUNTS,
    SCENES,
    TARGET_MS,
    Replay,
    Result,
    figures,
    plot,
    plot_scale,
    run_paired,
    scale_scene,
    scene_cycles,
)


def test_figures_cover_both_modes_and_the_cluster_scale(tmp_path):
    results: list[Result] = []
    scenes = list(SCENES) + [scale_scene(n) for n in CLUSTER_COUNTS if n != 250]
    for scene in scenes:
        current, baseline = run_paired(scene_cycles(scene, 3))
        current.scene = baseline.scene = scene.name
        assert current.method == "pipeline" and baseline.method == BASELINE
        assert len(current.per_cycle_ms) == len(baseline.per_cycle_ms) == 3
        assert current.after_last_ms is not None and len(current.after_last_ms) == 3
        results += [current, baseline]
    figs = figures(results, Replay([0.3, 0.4, 0.5], [0.1, 0.2, 0.2]))
    radar = [f for f in figs if f.group == "radar"]
    scale = [f for f in figs if f.group == "scale"]
    assert len(radar) == 2 * len(SCENES) + 1 and len(scale) == len(CLUSTER_COUNTS)
    for f in radar[:-1]:
        assert f.unit == "ms" and f.baseline_value is not None and f.baseline_value > 0
        assert f.target == f"< {TARGET_MS:g} ms" and f.target_met == (f.value < TARGET_MS)
    assert [f.name for f in scale] == [f"radar: {n} clusters per cycle, median"
                                       for n in CLUSTER_COUNTS]
    assert all(f.to_json()["ratio"] is not None for f in scale)
    assert plot(results, tmp_path).stat().st_size > 0
    assert plot_scale(results, tmp_path).stat().st_size > 0
