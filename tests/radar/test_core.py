"""One radar's core: a cycle is tracked once its general frames are in; its quality list
is decoded once it is in; the extended frames, last on the bus, only annotate."""

from aeb_radar_camera.common.config.radar import (
    CycleSettings,
    Expect,
    PrefilterSettings,
    RadarSettings,
)
from aeb_radar_camera.services.radar.ars408 import (
    ObjectExtended,
    ObjectGeneral,
    ObjectQuality,
    object_cycle_frames,
)
from aeb_radar_camera.services.radar.core import RadarCore
from aeb_radar_camera.services.radar.detections import PROB_OF_EXIST
from tests.can_support import feed

KNOWN = CycleSettings(expect_quality=Expect.YES, expect_extended=Expect.YES)


def frames(k: int):
    objs = [ObjectGeneral(4, 12.0, 0.2, -1.0, 0.0, 0, 20.0),
            ObjectGeneral(9, 18.0, -2.0, 0.0, 0.0, 1, 5.0)]
    qual = [ObjectQuality(4, 1, 1, 1, 1, 2, 3), ObjectQuality(9, 1, 1, 1, 1, 2, 7)]
    ext = [ObjectExtended(4, 0.0, 0.0, 1, 0.0, 4.4, 1.8),
           ObjectExtended(9, 0.0, 0.0, 3, 0.0, 0.6, 0.6)]
    return [(f, 10.0 + 0.075 * k) for f in object_cycle_frames(objs, k, qual, ext)]


def test_tracking_runs_when_the_general_frames_are_in():
    core = RadarCore(RadarSettings().sensors[0], RadarSettings(cycle=KNOWN))
    cycle = frames(0)
    assert feed(core, cycle[:3]) == []          # status + 2 general
    assert len(core.tracker) == 2               # tracked already, before 4 more frames
    [result] = feed(core, cycle[3:])
    assert result.complete and result.n_detections == 2
    classes = {round(t.x_m): t.obj_class for t in result.tracks}
    assert classes == {12: 1, 18: 3}            # annotated from the extended frames


def test_a_prefilter_on_quality_waits_for_the_quality_frames():
    s = RadarSettings(cycle=KNOWN, prefilter=PrefilterSettings(min_prob_of_exist=5))
    core = RadarCore(s.sensors[0], s)
    cycle = frames(0)
    assert feed(core, cycle[:5]) == [] and len(core.tracker) == 0
    [result] = feed(core, cycle[5:])
    assert [round(t.x_m) for t in result.tracks] == [18]    # ProbOfExist 3 is dropped
    assert result.n_detections == 2 and result.n_prefiltered == 1


def test_a_cycle_closed_by_the_next_status_is_tracked_once():
    core = RadarCore(RadarSettings().sensors[0], RadarSettings(cycle=KNOWN))
    first = frames(0)
    feed(core, first[:4])                        # extended frames never come
    steps = core.tracker.last_t
    [late] = feed(core, frames(1)[:1])
    assert not late.complete and late.n_detections == 2
    assert core.tracker.last_t == steps          # not tracked a second time
    assert {t.obj_class for t in late.tracks} == {-1}


def test_quality_frames_are_decoded_before_the_extended_frames_arrive():
    core = RadarCore(RadarSettings().sensors[0], RadarSettings(cycle=KNOWN))
    cycle = frames(0)
    assert feed(core, cycle[:5]) == []           # status, 2 general, 2 quality
    tracked = core._tracked                      # white box: nothing else shows the order
    assert tracked is not None and tracked.quality_attached
    assert sorted(tracked.general.det.ints[PROB_OF_EXIST].tolist()) == [3, 7]
    [result] = feed(core, cycle[5:])
    assert result.complete and {t.obj_class for t in result.tracks} == {1, 3}


def test_a_quality_list_decoded_before_the_cycle_ends_counts_its_rejections_once():
    """One quality frame for an object the general list does not have."""
    core = RadarCore(RadarSettings().sensors[0], RadarSettings(cycle=KNOWN))
    objs = [ObjectGeneral(4, 12.0, 0.2, -1.0, 0.0, 0, 20.0),
            ObjectGeneral(6, 18.0, -2.0, 0.0, 0.0, 1, 5.0)]
    qual = [ObjectQuality(4, 1, 1, 1, 1, 2, 3), ObjectQuality(5, 1, 1, 1, 1, 2, 3)]
    ext = [ObjectExtended(4, 0.0, 0.0, 1, 0.0, 4.4, 1.8),
           ObjectExtended(6, 0.0, 0.0, 3, 0.0, 0.6, 0.6)]
    cycle = [(f, 10.0) for f in object_cycle_frames(objs, 0, qual, ext)]
    assert feed(core, cycle[:5]) == [] and core._tracked is not None
    assert core._tracked.quality_attached
    [result] = feed(core, cycle[5:])
    assert not result.complete
    assert core.rejected.snapshot() == {"unmatched_id:Obj_2_Quality": 1}
