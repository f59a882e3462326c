"""The pure core of one radar: its frames (already classified) and the current time in,
finished cycles (tracks) and its status out. No CAN, no Zenoh, no clocks.

Pipeline per cycle: assembly -> decode -> prefilter -> centroid merge -> Kalman tracker.

A cycle's lists are worked on as each one completes. The radar sends N general frames,
then N quality and N extended frames: the tracks depend on the general frames alone
(unless a prefilter uses the quality frames), so the general list is decoded and
tracked as soon as it is in, the quality list decoded as soon as it is in, and the
extended list, which only annotates the object class, when the cycle is complete.
"""

from collections import deque
from dataclasses import dataclass
from statistics import median

from aeb_radar_camera.common.config.radar import RadarSettings, SensorSettings
from aeb_radar_camera.common.counters import ReasonCounter
from aeb_radar_camera.common.messages.header import Header
from aeb_radar_camera.common.messages.radar import (
    BUS_NOT_READY,
    BusState,
    OutputMode,
    RadarState,
    RadarStatus,
    RadarTrack,
)
from aeb_radar_camera.services.radar.ars408.codec import RadarFrame, RadarFrameError, decode
from aeb_radar_camera.services.radar.ars408.records import (
    ClusterListStatus,
    ObjectListStatus,
    RadarStateFrame,
    Version,
)
from aeb_radar_camera.services.radar.ars408.table import BY_KIND, Kind, MessageSpec
from aeb_radar_camera.services.radar.assembly import CycleAssembler, ListRole, RawCycle
from aeb_radar_camera.services.radar.configure import ConfigWriter
from aeb_radar_camera.services.radar.detections import (
    GeneralFrames,
    attach_extras,
    attach_list,
    decode_general,
    merge,
    prefilter,
)
from aeb_radar_camera.services.radar.tracker import KalmanTracker

# List messages by base ID: output mode, list role, the message's DLC.
_LIST_ROLES: dict[int, tuple[OutputMode, int, int]] = {
    BY_KIND[kind].base_id: (mode, role, BY_KIND[kind].dlc) for kind, mode, role in (
        (Kind.OBJECT_GENERAL, OutputMode.OBJECTS, ListRole.GENERAL),
        (Kind.OBJECT_QUALITY, OutputMode.OBJECTS, ListRole.QUALITY),
        (Kind.OBJECT_EXTENDED, OutputMode.OBJECTS, ListRole.EXTENDED),
        (Kind.CLUSTER_GENERAL, OutputMode.CLUSTERS, ListRole.GENERAL),
        (Kind.CLUSTER_QUALITY, OutputMode.CLUSTERS, ListRole.QUALITY),
    )
}

_ERROR_BITS = (
    ("persistent_error", "persistent error"),
    ("interference", "interference"),
    ("temperature_error", "temperature error"),
    ("temporary_error", "temporary error"),
    ("voltage_error", "voltage error"),
)

_PERIODS_KEPT = 32


@dataclass
class _Tracked:
    """A cycle whose general frames went through prefilter, merge and tracker."""

    cycle: RawCycle
    general: GeneralFrames
    n_prefiltered: int
    extras_attached: bool           # before tracking (the prefilter needs them)
    quality_attached: bool = False  # after tracking, once the quality list was in


@dataclass(frozen=True)
class TrackedCycle:
    """One finished cycle: what RadarTracks is built from (the shell adds header and timing)."""

    mode: OutputMode
    meas_counter: int
    complete: bool
    closed_by: str
    n_detections: int
    n_prefiltered: int
    stamp_wall_ns: int
    last_frame_mono_ns: int
    tracks: tuple[RadarTrack, ...]


def radar_state_message(f: RadarStateFrame) -> RadarState:
    return RadarState(
        nvm_read_ok=bool(f.nvm_read_ok), max_distance_m=int(f.max_distance_m),
        persistent_error=bool(f.persistent_error), interference=bool(f.interference),
        temperature_error=bool(f.temperature_error), temporary_error=bool(f.temporary_error),
        voltage_error=bool(f.voltage_error), sensor_id=f.sensor_id, sort_index=f.sort_index,
        motion_rx_state=f.motion_rx_state, send_ext_info=bool(f.send_ext_info),
        send_quality=bool(f.send_quality), output_type=f.output_type,
        rcs_threshold=f.rcs_threshold,
    )


class RadarCore:
    """One radar (one SensorID). Frames rejected by this radar's pipeline are counted in
    `rejected` by reason (``wrong_dlc:<message>``, ``out_of_range:<signal>``, cycle
    assembly reasons, ...)."""

    def __init__(self, sensor: SensorSettings, settings: RadarSettings) -> None:
        self.sensor = sensor
        self.settings = settings
        self.rejected = ReasonCounter()
        self.assembler = CycleAssembler(settings.cycle, self.rejected, self._list_in)
        self.tracker = KalmanTracker(settings.tracker)
        self.writer = ConfigWriter(sensor.configure, sensor.sensor_id)
        self.radar_state: RadarState | None = None
        self.firmware = ""
        self.frames_total = 0
        self.cycles_total = 0
        self.cycles_incomplete = 0
        self.meas_counter_gaps = 0
        self.last_cycle_mono_ns: int | None = None
        self._periods_s: deque[float] = deque(maxlen=_PERIODS_KEPT)
        self._last_status_t: float | None = None
        self._last_counter: int | None = None
        self._counter_step: int | None = None
        p = settings.prefilter
        # Only these optional filters need the quality frames before tracking.
        self._filter_needs_extras = p.min_prob_of_exist > 0 or bool(
            p.drop_cluster_invalid_states)
        self._tracked: _Tracked | None = None     # the open cycle, once tracked

    # -- frames -------------------------------------------------------------------------

    def on_frame(
        self, spec: MessageSpec, data: bytes, t_s: float, wall_ns: int, mono_ns: int
    ) -> list[TrackedCycle]:
        """One frame of this radar. `t_s` is the frame's source time (seconds; the log's
        time in a replay), `wall_ns` / `mono_ns` the host's receive times."""
        self.frames_total += 1
        role = _LIST_ROLES.get(spec.base_id)
        if role is not None:
            mode, list_role, dlc = role
            usable: bytes | None = data
            if not dlc <= len(data) <= 8:
                self.rejected.add(f"wrong_dlc:{spec.dbc_name}")
                usable = None   # arrived, so the cycle need not wait for it; marks it incomplete
            done = self.assembler.on_list_frame(mode, list_role, usable, mono_ns)
            return [self.process(c) for c in done] if done else []
        try:
            record = decode(spec, data)
        except RadarFrameError as exc:
            self.rejected.add(f"{exc.reason}:{spec.dbc_name}")
            return []
        if isinstance(record, ObjectListStatus):
            return self._status(OutputMode.OBJECTS, record.n_objects, record.meas_counter,
                                t_s, wall_ns, mono_ns)
        if isinstance(record, ClusterListStatus):
            return self._status(OutputMode.CLUSTERS, record.n_near + record.n_far,
                                record.meas_counter, t_s, wall_ns, mono_ns)
        if isinstance(record, RadarStateFrame):
            self.radar_state = radar_state_message(record)
            self.writer.on_state(record)
        elif isinstance(record, Version):
            self.firmware = f"{record.major}.{record.minor}.{record.patch}"
        else:
            self.rejected.add(f"host_frame:{spec.dbc_name}")
        return []

    def _status(
        self, mode: OutputMode, announced: int, counter: int, t_s: float, wall_ns: int,
        mono_ns: int,
    ) -> list[TrackedCycle]:
        self._count_gaps(counter)
        if self._last_status_t is not None:
            period = t_s - self._last_status_t
            if 0 < period < 1.0:
                self._periods_s.append(period)
        self._last_status_t = t_s
        return self._finish(
            self.assembler.on_status(mode, announced, counter, t_s, wall_ns, mono_ns))

    def _count_gaps(self, counter: int) -> None:
        """The MeasCounter advances by a fixed step per cycle (2 on the recording's radar):
        a larger step means status frames were lost."""
        last, self._last_counter = self._last_counter, counter
        if last is None:
            return
        step = (counter - last) % 65536
        if step == 0:
            return
        if self._counter_step is None or step < self._counter_step:
            self._counter_step = step
        if step <= 100 * self._counter_step:     # larger: a restart or a replay loop
            self.meas_counter_gaps += step // self._counter_step - 1

    def poll(self, mono_ns: int) -> list[TrackedCycle]:
        return self._finish(self.assembler.poll(mono_ns))

    def flush(self) -> list[TrackedCycle]:
        return self._finish(self.assembler.flush())

    def config_frames(self, mono_ns: int, start: bool = False) -> list[RadarFrame]:
        """0x200 frames to send now (at bus open with `start`, else re-sends when late)."""
        return self.writer.start(mono_ns) if start else self.writer.poll(mono_ns)

    # -- cycles -------------------------------------------------------------------------

    def _finish(self, cycles: list[RawCycle]) -> list[TrackedCycle]:
        return [self.process(c) for c in cycles]

    def _list_in(self, cycle: RawCycle, role: int) -> None:
        """All frames of one of the open cycle's lists are in (the assembler says so):
        track the cycle once its general list is (unless the prefilter waits for the
        quality list), decode the quality list into a tracked cycle's detections."""
        tracked = self._tracked if self._tracked is not None and \
            self._tracked.cycle is cycle else None
        if role == ListRole.GENERAL and tracked is None and not self._filter_needs_extras:
            self._tracked = self._track(cycle)
        elif role == ListRole.QUALITY and tracked is not None and not tracked.quality_attached:
            attach_list(cycle, tracked.general, ListRole.QUALITY)
            tracked.quality_attached = True

    def _track(self, cycle: RawCycle) -> _Tracked:
        g = decode_general(cycle)
        attached = self._filter_needs_extras
        if attached:
            attach_extras(cycle, g)
        kept = prefilter(g.det, self.settings.prefilter)
        self.tracker.step(merge(kept, self.settings.merge), cycle.t_s)
        return _Tracked(cycle, g, len(kept), attached)

    def process(self, cycle: RawCycle) -> TrackedCycle:
        """A finished cycle: tracked (now, or earlier when its general frames were in),
        its extra frames decoded, its result built."""
        tracked, self._tracked = self._tracked, None
        done = tracked if tracked is not None and tracked.cycle is cycle else self._track(cycle)
        g = done.general
        if not done.extras_attached:
            attach_extras(cycle, g, quality=not done.quality_attached)
            if cycle.mode is OutputMode.OBJECTS:
                self.tracker.annotate_class(g.det)
        for reason, n in g.rejected.items():
            self.rejected.add(reason, n)
        t = self.settings.tracker
        tracks = tuple(self.tracker.tracks())
        if t.drop_receding:
            tracks = tuple(tr for tr in tracks if not tr.range_rate_mps > t.receding_min_mps)
        complete = cycle.complete and not g.rejected
        self.cycles_total += 1
        self.cycles_incomplete += not complete
        self.last_cycle_mono_ns = cycle.last_frame_mono_ns
        return TrackedCycle(
            mode=cycle.mode, meas_counter=cycle.meas_counter, complete=complete,
            closed_by=cycle.closed_by, n_detections=len(g.det),
            n_prefiltered=done.n_prefiltered, stamp_wall_ns=cycle.stamp_wall_ns,
            last_frame_mono_ns=cycle.last_frame_mono_ns, tracks=tracks,
        )

    # -- status -------------------------------------------------------------------------

    @property
    def cycle_period_ms(self) -> float:
        return median(self._periods_s) * 1000.0 if self._periods_s else 0.0

    def not_ready_reason(self, bus_state: BusState, mono_ns: int) -> str:
        """Empty when the radar is ready: bus active, cycles arriving, configuration
        confirmed (when written), no error bit in 0x201."""
        if bus_state is not BusState.ACTIVE:
            return BUS_NOT_READY[bus_state]
        if self.last_cycle_mono_ns is None:
            return "no radar cycle received yet"
        silent_ns = int(self.settings.can.silent_after_s * 1e9)
        if mono_ns - self.last_cycle_mono_ns > silent_ns:
            return f"no cycle from sensor_id {self.sensor.sensor_id} recently"
        reason = self.writer.not_ready_reason()
        if reason:
            return reason
        if self.radar_state is not None:
            errors = [text for name, text in _ERROR_BITS if getattr(self.radar_state, name)]
            if errors:
                return "radar reports " + ", ".join(errors)
        return ""

    def status(
        self, header: Header, bus_state: BusState, mono_ns: int, interface: str,
        channel: str, frames_per_s: float, bus_reopens: int, bus_rejected: dict[str, int],
        ego_motion_frames_sent: int,
    ) -> RadarStatus:
        reason = self.not_ready_reason(bus_state, mono_ns)
        return RadarStatus(
            header=header, sensor=self.sensor.name, ready=not reason, not_ready_reason=reason,
            bus_state=bus_state, interface=interface, channel=channel,
            radar_state=self.radar_state, firmware=self.firmware,
            cycle_period_ms=self.cycle_period_ms, frames_per_s=frames_per_s,
            cycles_total=self.cycles_total, cycles_incomplete=self.cycles_incomplete,
            bus_reopens=bus_reopens, rejected={**bus_rejected, **self.rejected.snapshot()},
            sensor_id=self.sensor.sensor_id, meas_counter_gaps=self.meas_counter_gaps,
            tracker_resets=self.tracker.resets, ego_motion_frames_sent=ego_motion_frames_sent,
            tracks_resumed=self.tracker.resumed,
        )
