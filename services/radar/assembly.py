"""Cycle assembly for one radar: status frame, then its list frames, into one `RawCycle`.

Pure: frames and the current monotonic time in, finished cycles out.

Rules (ARS408.md): the status message's count is the authority. A cycle is emitted as
soon as it is complete (all announced general frames, plus quality / extended frames when
the radar sends them); a new status message closes the previous cycle, complete or not;
so does a timeout (the radar stopped mid-cycle) or the end of a replay. A cycle with
missing or rejected frames is marked incomplete and still emitted, never dropped.

Whether quality / extended frames are sent is fixed by config or learned from the stream
(what the previous cycle carried); until it is known, a cycle waits for the next status.
"""

from collections.abc import Callable
from dataclasses import dataclass, field

from aeb_radar_camera.common.config.radar import CycleSettings, Expect
from aeb_radar_camera.common.counters import ReasonCounter
from aeb_radar_camera.common.messages.radar import OutputMode


class ListRole:
    """Index of a list frame's kind within a cycle (RawCycle.lists)."""

    GENERAL = 0
    QUALITY = 1
    EXTENDED = 2


class ClosedBy:
    COMPLETE = "complete"
    NEXT_STATUS = "next_status"
    TIMEOUT = "timeout"
    END = "end"


@dataclass(slots=True)
class RawCycle:
    """The frames of one cycle, undecoded. A None entry is a frame that arrived but was
    rejected (wrong DLC): it counts as arrived, and makes the cycle incomplete."""

    mode: OutputMode
    meas_counter: int
    announced: int
    t_s: float                     # the status frame's time (source clock, for the tracker)
    stamp_wall_ns: int             # wall time the status frame was received
    start_mono_ns: int
    last_frame_mono_ns: int
    expect_quality: bool | None    # None: not known yet
    expect_extended: bool | None
    lists: tuple[list[bytes | None], list[bytes | None], list[bytes | None]] = field(
        default_factory=lambda: ([], [], []))
    remaining: int = 0             # frames still awaited (unknown expectations count)
    awaited: tuple[bool, bool, bool] = (True, True, True)   # by ListRole
    closed_by: str = ""
    complete: bool = False
    rejected_frames: int = 0       # None entries, counted as the assembler adds them

    def __post_init__(self) -> None:
        n = self.announced
        self.awaited = (True, self.expect_quality is not False,
                        self.expect_extended is not False)
        self.remaining = n * sum(self.awaited)

    @property
    def general(self) -> list[bytes | None]:
        return self.lists[ListRole.GENERAL]

    @property
    def quality(self) -> list[bytes | None]:
        return self.lists[ListRole.QUALITY]

    @property
    def extended(self) -> list[bytes | None]:
        return self.lists[ListRole.EXTENDED]

    def frames_for(self, role: int) -> list[bytes | None]:
        return self.lists[role]

    def all_arrived(self, quality: bool | None, extended: bool | None) -> bool:
        """All announced frames arrived, counting unknown expectations as expected."""
        n = self.announced
        if len(self.general) < n:
            return False
        if quality is not False and len(self.quality) < n:
            return False
        return not (extended is not False and len(self.extended) < n)



def _fixed(expect: Expect) -> bool | None:
    return None if expect is Expect.AUTO else expect is Expect.YES


class CycleAssembler:
    """Assembles the cycles of one radar. Rejections are counted in `rejected` by reason:
    ``no_cycle`` (list frame before any status), ``wrong_mode`` (cluster frame in an
    object cycle or the reverse), ``excess`` (more frames than announced),
    ``after_complete`` (a frame of an already emitted cycle that nobody expected)."""

    def __init__(self, settings: CycleSettings, rejected: ReasonCounter | None = None,
                 on_list_in: Callable[[RawCycle, int], None] | None = None) -> None:
        """`on_list_in(cycle, role)` is called when every announced frame of one of the
        open cycle's lists has arrived and the cycle still waits for others (a list
        that completes the cycle arrives with it)."""
        self.settings = settings
        self.rejected = rejected if rejected is not None else ReasonCounter()
        self._on_list_in = on_list_in
        self._timeout_ns = int(settings.timeout_s * 1e9)
        self._current: RawCycle | None = None
        self._emitted = False
        self._learned: dict[tuple[OutputMode, int], bool] = {}

    def _expectation(self, mode: OutputMode, role: int) -> bool | None:
        if role == ListRole.EXTENDED and mode is OutputMode.CLUSTERS:
            return False
        fixed = _fixed(self.settings.expect_quality if role == ListRole.QUALITY
                       else self.settings.expect_extended)
        if fixed is not None:
            return fixed
        return self._learned.get((mode, role))

    def _learn(self, cycle: RawCycle) -> None:
        if cycle.announced == 0:
            return
        for role in (ListRole.QUALITY, ListRole.EXTENDED):
            if cycle.mode is OutputMode.CLUSTERS and role == ListRole.EXTENDED:
                continue
            self._learned[(cycle.mode, role)] = len(cycle.frames_for(role)) > 0

    def _close(self, closed_by: str) -> list[RawCycle]:
        cycle = self._current
        if cycle is None or self._emitted:
            return []
        self._learn(cycle)
        quality = self._expectation(cycle.mode, ListRole.QUALITY)
        extended = self._expectation(cycle.mode, ListRole.EXTENDED)
        cycle.closed_by = closed_by
        cycle.complete = cycle.all_arrived(quality, extended) and not cycle.rejected_frames
        self._emitted = True
        return [cycle]

    def on_status(
        self, mode: OutputMode, announced: int, meas_counter: int,
        t_s: float, wall_ns: int, mono_ns: int,
    ) -> list[RawCycle]:
        """A status frame: closes the open cycle (emitted if it was not yet) and opens a
        new one, emitted at once when it announces nothing."""
        out = self._close(ClosedBy.NEXT_STATUS)
        self._current = RawCycle(
            mode=mode, meas_counter=meas_counter, announced=announced, t_s=t_s,
            stamp_wall_ns=wall_ns, start_mono_ns=mono_ns, last_frame_mono_ns=mono_ns,
            expect_quality=self._expectation(mode, ListRole.QUALITY),
            expect_extended=self._expectation(mode, ListRole.EXTENDED),
        )
        self._emitted = False
        if announced == 0:
            out += self._close(ClosedBy.COMPLETE)
        return out

    def on_list_frame(
        self, mode: OutputMode, role: int, data: bytes | None, mono_ns: int
    ) -> list[RawCycle]:
        """A general / quality / extended frame (`data` None when it was rejected)."""
        cycle = self._current
        if cycle is None:
            self.rejected.add("no_cycle")
            return []
        if mode is not cycle.mode:
            self.rejected.add("wrong_mode")
            return []
        frames = cycle.lists[role]
        if len(frames) >= cycle.announced:
            self.rejected.add("excess")
            return []
        if self._emitted:
            # The cycle went out believing these frames were not sent: expect them now on.
            self.rejected.add("after_complete")
            if role != ListRole.GENERAL:
                self._learned[(mode, role)] = True
            return []
        frames.append(data)
        cycle.last_frame_mono_ns = mono_ns
        if data is None:
            cycle.rejected_frames += 1
        # Unknown expectations count as awaited: such a cycle completes only when every
        # possible frame arrived, else it waits for the next status message.
        if cycle.awaited[role]:
            cycle.remaining -= 1
            if cycle.remaining == 0:
                return self._close(ClosedBy.COMPLETE)
        if len(frames) == cycle.announced and self._on_list_in is not None:
            self._on_list_in(cycle, role)
        return []

    def poll(self, mono_ns: int) -> list[RawCycle]:
        """Close an open cycle older than the timeout (the radar stopped mid-cycle)."""
        cycle = self._current
        if cycle is not None and not self._emitted and \
                mono_ns - cycle.start_mono_ns > self._timeout_ns:
            return self._close(ClosedBy.TIMEOUT)
        return []

    def flush(self) -> list[RawCycle]:
        """End of input: emit the open cycle, if any."""
        return self._close(ClosedBy.END)
