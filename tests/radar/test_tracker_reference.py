"""The vectorised merge and tracker give the same tracks as the previous code
(benchmarks/radar_reference.py, kept verbatim) on the benchmark's scenes and the real
recording: same track IDs, confirmation, hits, misses and radar attributes every cycle,
the same numbers to rounding."""

import pytest

from benchmarks.bench_radar import CYCLE_S, SCENES, scale_scene, scene_cycles
from benchmarks.radar_reference import ReferenceCore
from common.config.radar import RadarSettings
from services.radar.ars408 import classify
from services.radar.core import CycleResult, RadarCore
from tests.can_support import recording_frames

_EXACT = ("track_id", "confirmed", "hits", "misses", "radar_object_id", "dyn_prop",
          "obj_class")
_CLOSE = ("x_m", "y_m", "vx_mps", "vy_mps", "range_m", "range_rate_mps", "rcs_dbsm",
          "x_var_m2", "y_var_m2")


def assert_same_results(new: list[CycleResult], old: list[CycleResult]) -> None:
    assert len(new) == len(old) > 0
    for k, (a, b) in enumerate(zip(new, old, strict=True)):
        assert (a.n_detections, a.n_prefiltered, a.complete) == \
            (b.n_detections, b.n_prefiltered, b.complete), f"cycle {k}"
        assert [[getattr(t, f) for f in _EXACT] for t in a.tracks] == \
            [[getattr(t, f) for f in _EXACT] for t in b.tracks], f"cycle {k}"
        for ta, tb in zip(a.tracks, b.tracks, strict=True):
            for f in _CLOSE:
                assert getattr(ta, f) == pytest.approx(getattr(tb, f), rel=1e-9, abs=1e-9), \
                    f"cycle {k} track {ta.track_id} {f}"


def run(core_type: type[RadarCore], cycles) -> list[CycleResult]:
    s = RadarSettings()
    core = core_type(s.sensors[0], s)
    out: list[CycleResult] = []
    for k, frames in enumerate(cycles):
        for spec, data in frames:
            out += core.on_frame(spec, data, k * CYCLE_S, 0, 0)
    return out


@pytest.mark.parametrize("scene", [*SCENES, scale_scene(500)], ids=lambda s: s.name)
def test_same_tracks_as_the_previous_tracker_on_the_benchmark_scenes(scene):
    cycles = scene_cycles(scene, 25, seed=7)
    new = run(RadarCore, cycles)
    assert sum(len(r.tracks) for r in new) > 25      # the scenes are really tracked
    assert_same_results(new, run(ReferenceCore, cycles))


def test_same_tracks_as_the_previous_tracker_on_the_recording():
    frames = [(classify(f.arb_id)[0], f.data, t) for f, t in recording_frames()]  # type: ignore[index]

    def replay(core_type: type[RadarCore]) -> list[CycleResult]:
        s = RadarSettings()
        core = core_type(s.sensors[0], s)
        out: list[CycleResult] = []
        for spec, data, t in frames:
            out += core.on_frame(spec, data, t, 0, 0)
        return out + core.flush()

    new = replay(RadarCore)
    assert any(t.confirmed for r in new for t in r.tracks)
    assert_same_results(new, replay(ReferenceCore))
