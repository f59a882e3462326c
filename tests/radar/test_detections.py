"""Decoding a cycle's frames into detections, the prefilter and the centroid merge."""

import numpy as np
import pytest

from aeb_radar_camera.common.config.radar import MergeSettings, PrefilterSettings
from aeb_radar_camera.common.messages.radar import OutputMode
from aeb_radar_camera.services.radar.ars408 import (
    BY_KIND,
    ClusterGeneral,
    ClusterQuality,
    Kind,
    ObjectExtended,
    ObjectGeneral,
    ObjectQuality,
    encode,
)
from aeb_radar_camera.services.radar.assembly import RawCycle
from aeb_radar_camera.services.radar.detections import (
    INVALID_STATE,
    OBJ_CLASS,
    PROB_OF_EXIST,
    UNKNOWN,
    Detections,
    decode_cycle,
    merge,
    prefilter,
)
from aeb_radar_camera.services.radar.neighbours import pairs_within_self


def raw_cycle(mode, general, quality=(), extended=()):
    c = RawCycle(mode=mode, meas_counter=0, announced=len(general), t_s=0.0, stamp_wall_ns=0,
                 start_mono_ns=0, last_frame_mono_ns=0, expect_quality=None,
                 expect_extended=None)
    c.general.extend(general)
    c.quality.extend(quality)
    c.extended.extend(extended)
    return c


def data(record):
    return encode(record).data


def test_objects_with_quality_and_extended_matched_by_id_in_any_order():
    objs = [ObjectGeneral(7, 10.0, 1.0, -2.0, 0.5, 0, 12.0),
            ObjectGeneral(3, 20.0, -1.0, 0.0, 0.0, 1, -5.0)]
    qual = [ObjectQuality(3, 1, 1, 1, 1, 2, 4), ObjectQuality(7, 1, 1, 1, 1, 2, 6)]
    ext = [ObjectExtended(7, 0.0, 0.0, 3, 0.0, 0.6, 0.6)]
    det, rejected = decode_cycle(raw_cycle(OutputMode.OBJECTS, [data(o) for o in objs],
                                           [data(q) for q in qual], [data(e) for e in ext]))
    assert rejected == {}
    assert det.x.tolist() == pytest.approx([10.0, 20.0])
    assert det.y.tolist() == pytest.approx([1.0, -1.0])
    assert det.vx.tolist() == pytest.approx([-2.0, 0.0])
    assert det.radar_id.tolist() == [7, 3]
    assert det.i[:, PROB_OF_EXIST].tolist() == [6, 4]
    assert det.i[:, OBJ_CLASS].tolist() == [3, UNKNOWN]    # no extended frame for ID 3


def test_duplicate_unmatched_and_out_of_range_frames_are_counted_not_used():
    good = ObjectGeneral(1, 10.0, 0.0, 0.0, 0.0, 0, 0.0)
    dup = ObjectGeneral(1, 30.0, 0.0, 0.0, 0.0, 0, 0.0)
    bad = bytes(8)                                   # DistLong raw 0 = -500 m
    det, rejected = decode_cycle(raw_cycle(
        OutputMode.OBJECTS, [data(good), data(dup), bad, None],
        [data(ObjectQuality(9, 0, 0, 0, 0, 2, 7)), data(ObjectQuality(0, 0, 0, 0, 0, 2, 7))]))
    assert det.x.tolist() == pytest.approx([10.0])   # the first frame of ID 1 wins
    assert rejected == {"duplicate_id:Obj_1_General": 1,
                        "out_of_range:Obj_DistLong": 1,
                        "unmatched_id:Obj_2_Quality": 1}   # ID 9; ID 0 was the bad frame


def test_more_than_256_clusters_keep_every_frame_and_pair_quality_by_occurrence():
    clusters = [ClusterGeneral(i % 256, 5.0 + i * 0.2, 0.0, 0.0, 0.0, 0, 0.0)
                for i in range(300)]
    quality = [ClusterQuality(i % 256, 0, 0, 0, 0, 1, 3, i % 2) for i in range(300)]
    quality.reverse()   # out of order: matched by (ID, occurrence), not by position
    det, rejected = decode_cycle(raw_cycle(OutputMode.CLUSTERS, [data(c) for c in clusters],
                                           [data(q) for q in quality]))
    assert rejected == {} and len(det) == 300
    # Occurrences pair up: quality frame i carries invalid_state i % 2.
    assert det.i[:, INVALID_STATE].tolist() == [i % 2 for i in range(300)]


def test_prefilter_is_the_papers():
    det = Detections.of(
        x=[10.0, 25.0, 25.01, -1.0, 5.0, 5.0, 0.0, 24.0],
        y=[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 7.0],
        rcs=[0.0, 0.0, 0.0, 0.0, -20.0, -19.5, 5.0, 0.0],
    )
    kept = prefilter(det, PrefilterSettings())
    # 25 m is in, 25.01 out; behind out; RCS -20 out, -19.5 in; range 0 out;
    # (24, 7) has range 25.0: in.
    assert kept.x.tolist() == pytest.approx([10.0, 25.0, 5.0, 24.0])
    assert kept.rcs.tolist() == pytest.approx([0.0, 0.0, -19.5, 0.0])


def test_optional_prefilters():
    det = Detections.of(x=[5.0, 6.0, 7.0], y=0.0, prob_of_exist=[2, 6, UNKNOWN],
                        invalid_state=[0, 6, 7])
    assert prefilter(det, PrefilterSettings(min_prob_of_exist=5)).x.tolist() == [6.0, 7.0]
    kept = prefilter(det, PrefilterSettings(drop_cluster_invalid_states=(6, 7)))
    assert kept.x.tolist() == [5.0]
    backward = Detections.of(x=[-5.0], y=0.0)
    assert len(prefilter(backward, PrefilterSettings(forward_only=False))) == 1


def test_merge_several_returns_of_one_object_into_their_centroid():
    det = Detections.of(x=[10.0, 10.6, 10.3, 30.0], y=[0.0, 0.4, -0.5, 0.0],
                        vx=[-3.0, -3.2, -2.9, -3.0], rcs=[5.0, 12.0, 1.0, 0.0],
                        radar_id=[1, 2, 3, 4])
    merged = merge(det, MergeSettings())
    assert len(merged) == 2
    car = int(np.argmin(merged.x))
    assert merged.x[car] == pytest.approx((10.0 + 10.6 + 10.3) / 3)
    assert merged.y[car] == pytest.approx((0.0 + 0.4 - 0.5) / 3)
    assert merged.vx[car] == pytest.approx((-3.0 - 3.2 - 2.9) / 3)
    assert merged.rcs[car] == 12.0 and merged.radar_id[car] == 2    # the seed's


def test_merge_keeps_close_detections_with_different_velocities_apart():
    det = Detections.of(x=[10.0, 10.5], y=[0.0, 0.3], vx=[-5.0, 0.0])
    assert len(merge(det, MergeSettings())) == 2


def test_merge_uses_seeds_not_chains():
    # Returns every 1 m along a guard rail: chaining would collapse them into one point.
    det = Detections.of(x=np.arange(5.0, 15.0), y=3.0, rcs=np.arange(10.0))
    merged = merge(det, MergeSettings(distance_m=1.5))
    assert 3 <= len(merged) <= 5
    assert merged.x.max() - merged.x.min() >= 7.0


def test_merge_can_be_disabled():
    det = Detections.of(x=[10.0, 10.1], y=0.0)
    assert len(merge(det, MergeSettings(enabled=False))) == 2


@pytest.mark.parametrize("n", [5, 200])      # every pair tested, and the sorted window
def test_the_pair_search_finds_exactly_the_near_pairs(n):
    rng = np.random.default_rng(n)
    ax, ay = rng.uniform(0, 20, n), rng.uniform(-5, 5, n)
    i, j = pairs_within_self(ax, ay, 2.0)
    d = np.hypot(ax[:, None] - ax[None, :], ay[:, None] - ay[None, :])
    expect = {(a, b) for a, b in zip(*[v.tolist() for v in np.nonzero(d <= 2.0)], strict=True)
              if a < b}
    assert {(min(a, b), max(a, b)) for a, b in zip(i.tolist(), j.tolist(), strict=True)} \
        == expect and len(i) == len(expect)


def kept_by_the_rule(det: Detections, s: PrefilterSettings) -> list[int]:
    """The prefilter's rule read detection by detection."""
    out = []
    for j, (x, y, rcs) in enumerate(zip(det.x.tolist(), det.y.tolist(), det.rcs.tolist(),
                                        strict=True)):
        p, state = int(det.ints[PROB_OF_EXIST, j]), int(det.ints[INVALID_STATE, j])
        if (s.min_range_m**2 < x * x + y * y <= s.max_range_m**2 and rcs > s.min_rcs_dbsm
                and (x > 0 or not s.forward_only)
                and (s.min_prob_of_exist == 0 or p == UNKNOWN or p >= s.min_prob_of_exist)
                and state not in s.drop_cluster_invalid_states):
            out.append(j)
    return out


@pytest.mark.parametrize("settings", [
    PrefilterSettings(),
    PrefilterSettings(forward_only=False, min_range_m=2.0, max_range_m=40.0, min_rcs_dbsm=0.0),
    PrefilterSettings(min_prob_of_exist=4, drop_cluster_invalid_states=(1, 6, 7)),
])
@pytest.mark.parametrize("n", [1, 3, 16, 250])
def test_the_prefilter_keeps_what_its_rule_keeps_at_every_size(settings, n):
    rng = np.random.default_rng(9 + n)
    for _ in range(30):
        det = Detections.of(rng.uniform(-10, 60, n).round(1), rng.uniform(-30, 30, n),
                            rng.uniform(-5, 5, n), 0.0, rng.uniform(-30, 30, n).round(),
                            radar_id=np.arange(n), prob_of_exist=rng.integers(-1, 8, n),
                            invalid_state=rng.integers(-1, 9, n))
        kept = prefilter(det, settings)
        expect = kept_by_the_rule(det, settings)
        assert kept.radar_id.tolist() == expect
        assert np.array_equal(kept.floats, det.floats[:, expect])


@pytest.mark.parametrize("mode", [OutputMode.OBJECTS, OutputMode.CLUSTERS])
@pytest.mark.parametrize("n", [1, 4, 100])
def test_general_frames_decode_as_their_frames_one_by_one(mode, n):
    """Each valid frame a detection, in order; out-of-range frames dropped and counted;
    in object mode a repeated ID is a fault (the first frame of the ID wins, even a
    rejected one), in cluster mode a detection."""
    from aeb_radar_camera.services.radar.ars408 import RadarFrameError, decode
    from aeb_radar_camera.services.radar.detections import decode_general

    rng = np.random.default_rng(4 + n)
    make = ObjectGeneral if mode is OutputMode.OBJECTS else ClusterGeneral
    spec = BY_KIND[Kind.OBJECT_GENERAL if mode is OutputMode.OBJECTS else Kind.CLUSTER_GENERAL]
    for _ in range(50):
        ids = rng.integers(0, n + 2, n)            # now and then a repeated ID
        frames: list[bytes | None] = [
            data(make(int(k), round(float(rng.uniform(1, 100)), 1),
                      round(float(rng.uniform(-20, 20)), 1), -2.0, 0.5, int(rng.integers(0, 7)),
                      float(rng.integers(-10, 30)))) for k in ids]
        if rng.random() < 0.3:
            frames[int(rng.integers(0, n))] = bytes(8)        # DistLong -500 m
        expect: list = []
        rejected: dict[str, int] = {}
        seen: set[int] = set()
        for d in frames:
            assert d is not None
            first = d[0] not in seen
            seen.add(d[0])                          # the ID byte
            try:
                r = decode(spec, d)
            except RadarFrameError as exc:
                key = f"{exc.reason}:{spec.signals[1].dbc_name}"
                rejected[key] = rejected.get(key, 0) + 1
                continue
            if mode is OutputMode.OBJECTS and not first:
                key = f"duplicate_id:{spec.dbc_name}"
                rejected[key] = rejected.get(key, 0) + 1
                continue
            expect.append(r)
        g = decode_general(raw_cycle(mode, frames))
        assert g.rejected == rejected
        assert g.det.radar_id.tolist() == [r.id for r in expect]
        assert g.det.i[:, 1].tolist() == [r.dyn_prop for r in expect]
        assert np.array_equal(g.det.f[:, :5], np.array(
            [[r.dist_long_m, r.dist_lat_m, r.vrel_long_mps, r.vrel_lat_mps, r.rcs_dbsm]
             for r in expect]).reshape(-1, 5))
