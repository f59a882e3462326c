"""Cycle assembly: the status message's count is the authority; complete cycles go out at
their last frame; incomplete ones are counted and still emitted."""

from aeb_radar_camera.common.config.radar import CycleSettings, Expect
from aeb_radar_camera.common.messages.radar import OutputMode
from aeb_radar_camera.services.radar.assembly import ClosedBy, CycleAssembler, ListRole

OBJ = OutputMode.OBJECTS
CL = OutputMode.CLUSTERS
G, Q, E = ListRole.GENERAL, ListRole.QUALITY, ListRole.EXTENDED
D = b"\x00" * 8


def cycle(asm, n, counter, mode=OBJ, quality=True, extended=True, t=0.0, drop=()):
    """Feed one cycle; return what was emitted after each frame, as (frame, cycles)."""
    out: list[tuple[object, list]] = [("status", asm.on_status(mode, n, counter, t, 100, 1000))]
    roles = [G] + ([Q] if quality else []) + ([E] if extended and mode is OBJ else [])
    k = 0
    for role in roles:
        for i in range(n):
            k += 1
            if (role, i) not in drop:
                out.append(((role, i), asm.on_list_frame(mode, role, D, 1000 + k)))
    return out


def emitted(trace):
    return [(where, c) for where, cs in trace for c in cs]


def test_a_complete_cycle_goes_out_with_its_last_frame():
    asm = CycleAssembler(CycleSettings())
    trace = cycle(asm, 2, 10)
    [(where, c)] = emitted(trace)
    assert where == (E, 1) and c.meas_counter == 10      # not at the next status
    assert c.closed_by == ClosedBy.COMPLETE and c.complete
    assert len(c.general) == len(c.quality) == len(c.extended) == 2
    assert c.stamp_wall_ns == 100 and c.last_frame_mono_ns == 1006
    assert emitted(cycle(asm, 2, 12))[0][0] == (E, 1)


def test_learned_without_quality_and_extended_frames():
    asm = CycleAssembler(CycleSettings())
    assert emitted(cycle(asm, 3, 1, quality=False, extended=False)) == []   # not known yet
    trace = cycle(asm, 3, 2, quality=False, extended=False)
    first = trace[0][1][0]
    assert first.complete and first.closed_by == ClosedBy.NEXT_STATUS
    # Second cycle: general frames only, known now: emitted at its third general frame.
    assert trace[-1][0] == (G, 2) and trace[-1][1][0].closed_by == ClosedBy.COMPLETE


def test_fixed_expectations_publish_the_first_cycle_early():
    asm = CycleAssembler(CycleSettings(expect_quality=Expect.NO, expect_extended=Expect.NO))
    trace = cycle(asm, 2, 1, quality=False, extended=False)
    assert trace[-1][1][0].complete and trace[-1][1][0].closed_by == ClosedBy.COMPLETE


def test_empty_cycle_is_emitted_with_its_status():
    asm = CycleAssembler(CycleSettings())
    [c] = asm.on_status(OBJ, 0, 5, 0.0, 0, 0)
    assert c.complete and c.announced == 0 and c.closed_by == ClosedBy.COMPLETE


def test_missing_frame_closed_by_next_status_is_incomplete_and_still_emitted():
    asm = CycleAssembler(CycleSettings())
    cycle(asm, 2, 1)
    cycle(asm, 2, 2)                       # learns: quality and extended are sent
    trace = cycle(asm, 3, 3, drop={(Q, 1)})
    assert emitted(trace) == []            # waits: a quality frame is missing
    trace = cycle(asm, 1, 4)
    late = trace[0][1][0]
    assert late.meas_counter == 3 and not late.complete
    assert late.closed_by == ClosedBy.NEXT_STATUS
    assert (len(late.general), len(late.quality), len(late.extended)) == (3, 2, 3)


def test_rejected_frame_counts_as_arrived_but_marks_the_cycle_incomplete():
    asm = CycleAssembler(CycleSettings(expect_quality=Expect.NO, expect_extended=Expect.NO))
    asm.on_status(OBJ, 2, 1, 0.0, 0, 0)
    assert asm.on_list_frame(OBJ, G, None, 1) == []
    [c] = asm.on_list_frame(OBJ, G, D, 2)
    assert c.closed_by == ClosedBy.COMPLETE and not c.complete


def test_orphan_excess_wrong_mode_and_late_frames_are_counted():
    asm = CycleAssembler(CycleSettings(expect_quality=Expect.AUTO, expect_extended=Expect.NO))
    assert asm.on_list_frame(OBJ, G, D, 0) == []
    assert asm.rejected.get("no_cycle") == 1
    cycle(asm, 1, 1, extended=False, quality=False)
    cycle(asm, 1, 2, extended=False, quality=False)     # learned: no quality frames
    asm.on_status(OBJ, 1, 3, 0.0, 0, 0)
    [c] = asm.on_list_frame(OBJ, G, D, 1)
    assert c.complete
    assert asm.on_list_frame(OBJ, G, D, 2) == []
    assert asm.rejected.get("excess") == 1
    assert asm.on_list_frame(CL, G, D, 3) == []
    assert asm.rejected.get("wrong_mode") == 1
    # A quality frame after the cycle went out: counted, and expected from now on.
    assert asm.on_list_frame(OBJ, Q, D, 4) == []
    assert asm.rejected.get("after_complete") == 1
    asm.on_status(OBJ, 1, 4, 0.0, 0, 0)
    assert asm.on_list_frame(OBJ, G, D, 5) == []        # now waits for its quality frame
    [c] = asm.on_list_frame(OBJ, Q, D, 6)
    assert c.complete and len(c.quality) == 1


def test_timeout_closes_a_cycle_the_radar_abandoned():
    asm = CycleAssembler(CycleSettings(timeout_s=0.2))
    asm.on_status(CL, 3, 1, 0.0, 0, 1_000)
    asm.on_list_frame(CL, G, D, 2_000)
    assert asm.poll(1_000 + 100_000_000) == []
    [c] = asm.poll(1_000 + 250_000_000)
    assert c.closed_by == ClosedBy.TIMEOUT and not c.complete and c.last_frame_mono_ns == 2_000
    assert asm.poll(1_000 + 500_000_000) == []           # once only


def test_flush_emits_the_open_cycle_at_the_end_of_input():
    asm = CycleAssembler(CycleSettings())
    asm.on_status(OBJ, 2, 1, 0.0, 0, 0)
    asm.on_list_frame(OBJ, G, D, 1)
    [c] = asm.flush()
    assert c.closed_by == ClosedBy.END and not c.complete
    assert asm.flush() == []


def test_cluster_cycles_never_wait_for_extended_frames():
    asm = CycleAssembler(CycleSettings(expect_quality=Expect.YES))
    asm.on_status(CL, 2, 1, 0.0, 0, 0)
    asm.on_list_frame(CL, G, D, 1)
    asm.on_list_frame(CL, G, D, 2)
    asm.on_list_frame(CL, Q, D, 3)
    [c] = asm.on_list_frame(CL, Q, D, 4)
    assert c.complete and c.mode is CL and c.last_frame_mono_ns == 4


def test_each_list_is_reported_as_it_completes():
    lists_in: list[tuple[int, int]] = []
    asm = CycleAssembler(CycleSettings(expect_quality=Expect.YES, expect_extended=Expect.YES),
                         on_list_in=lambda cycle, role: lists_in.append((cycle.meas_counter, role)))
    asm.on_status(OBJ, 2, 1, 0.0, 0, 0)
    seen = []
    for i, role in enumerate((G, G, Q, Q, E)):
        assert asm.on_list_frame(OBJ, role, D, i) == []
        seen.append(list(lists_in))
    assert seen == [[], [(1, G)], [(1, G)], [(1, G), (1, Q)], [(1, G), (1, Q)]]
    [done] = asm.on_list_frame(OBJ, E, D, 5)     # the list that completes the cycle
    assert done.meas_counter == 1 and lists_in == [(1, G), (1, Q)]
    assert asm.on_list_frame(OBJ, E, D, 6) == []     # excess: nothing reported again
    asm.on_status(OBJ, 1, 2, 0.0, 0, 0)
    asm.on_list_frame(OBJ, G, D, 7)
    assert lists_in[-1] == (2, G)
