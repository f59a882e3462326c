"""The radar benchmark runs (its figures are printed by `python -m benchmarks.bench_radar`;
no timing is asserted here)."""

from benchmarks.bench_radar import (
    SCENES,
    Result,
    run_decode_only,
    run_pipeline,
    scene_cycles,
    table,
)


def test_benchmark_scenes_run_through_the_pipeline():
    results = []
    for scene in SCENES:
        cycles = scene_cycles(scene, 3)
        per_cycle, after_last = run_pipeline(cycles)
        assert len(per_cycle) == 3 and all(a <= p for a, p in zip(after_last, per_cycle,
                                                                    strict=True))
        results.append(Result(scene.name, "pipeline", per_cycle, after_last))
        results.append(Result(scene.name, "decode", run_decode_only(cycles, scene.mode)))
    assert "objects 100, spread" in table(results)
