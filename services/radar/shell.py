"""The radar service's I/O shell: reads the CAN bus (common/can_link.py: reopened with
exponential backoff when lost), feeds each radar's core, publishes tracks as soon as a
cycle is complete and status at a fixed period and on change, writes 0x200 / 0x300 /
0x301.

One thread reads the bus and runs the cores (so a cycle is processed the moment its last
frame arrives); ego-motion frames are written from the caller's thread (a Zenoh
callback) under the link's lock, which the configuration writes share.
"""

import logging
import statistics
import threading
from collections import deque
from collections.abc import Callable
from typing import Protocol

import can

from aeb_radar_camera.common.can_link import HOUSEKEEPING_NS, RECEIVE_TIMEOUT_NS, CanLink
from aeb_radar_camera.common.clock import NS_PER_S, mono_ns, wall_ns
from aeb_radar_camera.common.config.radar import RadarSettings
from aeb_radar_camera.common.counters import ReasonCounter
from aeb_radar_camera.common.log import RateLimitedLog, kv
from aeb_radar_camera.common.messages.header import Header
from aeb_radar_camera.common.messages.radar import (
    BusState,
    CanFrame,
    RadarStatus,
    RadarTracks,
    RawCanFrames,
    can_frame,
)
from aeb_radar_camera.common.messages.vehicle import EgoMotion
from aeb_radar_camera.common.systemd import Watchdog
from aeb_radar_camera.services.radar.ars408.codec import RadarFrame
from aeb_radar_camera.services.radar.ars408.table import classify
from aeb_radar_camera.services.radar.core import RadarCore, TrackedCycle
from aeb_radar_camera.services.radar.ego import EgoMotionForwarder
from aeb_radar_camera.services.radar.ports import SERVICE, CanPort, radar_message

_log = logging.getLogger("radar")

# The link's schedule, also 0x200 re-sends; tools/recording/rerun_radar.py imports it from
# here to keep house as the live loop does.
__all__ = ["HOUSEKEEPING_NS", "RECEIVE_TIMEOUT_NS", "RadarOutput", "RadarShell"]
# Raw frames not followed by a cycle (other traffic, a radar that stopped) still go out
# once the oldest is one radar cycle old.
_RAW_BATCH_MAX_AGE_NS = 75_000_000


class RadarOutput(Protocol):
    """Where the service publishes (Zenoh in production, a list in tests)."""

    def tracks(self, sensor: str, msg: RadarTracks) -> None: ...

    def status(self, sensor: str, msg: RadarStatus) -> None: ...

    def serving(self) -> None:
        """Called once, when the bus first opened: the service now serves."""


class RadarShell:
    """Rejections that belong to no single radar are counted in `bus_rejected`
    (``error_frame``, ``remote_frame``, ``extended_id``, ``unknown_id``, ``host_frame``,
    ``unconfigured_sensor_id``, ``internal_error``, ``bus_failure``, and lines the slcan
    reader dropped: ``slcan_malformed``, ``slcan_length``, ``slcan_unknown``,
    ``slcan_not_ascii``, ``slcan_too_long``) and reported in every radar's status under a
    ``bus:`` prefix.

    `raw_can`: where every received frame goes, in batches (RawCanFrames), when the
    raw frames are published (`[radar.raw_can]`); None: they are not kept."""

    def __init__(
        self,
        settings: RadarSettings,
        output: RadarOutput,
        port_factory: Callable[[], CanPort] | None = None,
        watchdog: Watchdog | None = None,
        raw_can: Callable[[RawCanFrames], None] | None = None,
    ) -> None:
        self.settings = settings
        self.watchdog = watchdog or Watchdog(env={})   # fed by the CAN loop
        self.output = output
        self._raw_sink = raw_can
        self._raw: list[CanFrame] = []
        self.cores = {s.sensor_id: RadarCore(s, settings) for s in settings.sensors}
        self.bus_rejected = ReasonCounter()
        self.link = CanLink(settings.can, settings.replay, SERVICE, self, self.bus_rejected,
                            port_factory, self.watchdog)
        self.interface, self.channel = self.link.interface, self.link.channel
        self.ego = EgoMotionForwarder(settings.ego_motion, list(self.cores))
        self.ego_sent: dict[int, int] = dict.fromkeys(self.cores, 0)
        self._served = False
        self._seq: dict[str, int] = {}
        self._status_due: dict[int, int] = dict.fromkeys(self.cores, 0)
        self._status_key: dict[int, object] = {}
        self._ready: dict[int, bool] = {}
        self._fps_sample: dict[int, tuple[int, int, float]] = {}
        self._rl = RateLimitedLog(_log)
        self._period_ns = int(settings.status_period_s * NS_PER_S)
        self._stats_period_ns = int(settings.stats_period_s * NS_PER_S)
        self._stats_due = 0
        # per radar, since the last stats line: (cycles, frames, mono) then, processing times
        self._stats_from: dict[int, tuple[int, int, int]] = {}
        self._processing_us: dict[int, deque[float]] = {
            sid: deque(maxlen=4096) for sid in self.cores}
        self._last_tracks: dict[int, tuple[int, int]] = dict.fromkeys(self.cores, (0, 0))

    # -- main loop ----------------------------------------------------------------------

    @property
    def bus_state(self) -> BusState:
        return self.link.bus_state

    def run(self, stop: threading.Event) -> int:
        """Serve until `stop` is set (or a non-looping replay ends with exit_at_end)."""
        if self.link.run(stop):
            return self._after_end(stop)
        self._publish_raw()
        self._publish_all_status(mono_ns(), wall_ns())
        self.log_stats(mono_ns())
        return 0

    # -- the link's handler -------------------------------------------------------------

    def opened(self, mono: int) -> None:
        if not self._served:
            self._served = True
            self.output.serving()
        for core in self.cores.values():
            self._send_frames(core.config_frames(mono, start=True))

    def waiting(self, mono: int, wall: int) -> None:
        self._status_tick(mono, wall)

    def bus_state_changed(self, mono: int) -> None:
        self._publish_all_status(mono, wall_ns())

    def _after_end(self, stop: threading.Event) -> int:
        for core in self.cores.values():
            self._publish_results(core, core.flush(), 0)
        self._publish_raw()
        self.link.end(mono_ns())
        _log.info(kv("replay_ended", cycles=sum(c.cycles_total for c in self.cores.values())))
        self.log_stats(mono_ns())
        if not self.settings.replay.exit_at_end:
            while not self.watchdog.wait(stop, self.settings.status_period_s):
                self._publish_all_status(mono_ns(), wall_ns())
        return 0

    # -- frames -------------------------------------------------------------------------

    def receive(self, msg: can.Message, wall_ns: int, mono_ns: int) -> None:
        """One frame at the given receive times: the serve loop's step, also for a re-run
        that passes recorded times (`aeb rerun radar`)."""
        self._on_message(msg, wall_ns, mono_ns)

    def tick(self, mono_ns: int, wall_ns: int) -> None:
        """The serve loop's housekeeping at the given time (timed-out cycles closed,
        status published), also for a re-run."""
        self._housekeeping(mono_ns, wall_ns)

    def _on_message(self, msg: can.Message, wall: int, mono: int) -> None:
        if self._raw_sink is not None:
            self._raw.append(can_frame(msg, wall, mono))
        if not self.link.accept(msg, mono):
            return
        if msg.is_remote_frame or msg.is_extended_id:
            self.bus_rejected.add("remote_frame" if msg.is_remote_frame else "extended_id")
            return
        found = classify(msg.arbitration_id)
        if found is None:
            self.bus_rejected.add("unknown_id")
            return
        spec, sensor_id = found
        if spec.sender != "ARS408":
            self.bus_rejected.add("host_frame")   # another host's (or our echoed) command
            return
        core = self.cores.get(sensor_id)
        if core is None:
            self.bus_rejected.add("unconfigured_sensor_id")
            return
        t_s = msg.timestamp if msg.timestamp > 0 else mono / NS_PER_S
        try:
            results = core.on_frame(spec, bytes(msg.data), t_s, wall, mono)
        except Exception as exc:
            # A bug in one frame's processing must not stop the radar's next cycles, which
            # feed the brake decision: count it, log it with its frame, go on.
            self.bus_rejected.add("internal_error")
            if self._rl.error("internal", "core_failed", sensor=core.sensor.name,
                              arb_id=hex(msg.arbitration_id), data=bytes(msg.data).hex(),
                              error=repr(exc)):
                _log.exception("core traceback")
            return
        if results:
            self._publish_results(core, results, mono_ns() - mono)
            # The cycle's frames right after its tracks, off the latency path.
            self._publish_raw()

    def _publish_raw(self, older_than_mono_ns: int | None = None) -> None:
        """The frames received since the last batch (when published and there are any;
        with `older_than_mono_ns`, only once the oldest is older than that)."""
        frames = self._raw
        if self._raw_sink is None or not frames or (
                older_than_mono_ns is not None and frames[0].rx_mono_ns > older_than_mono_ns):
            return
        self._raw = []
        raw = self.settings.raw_can
        self._raw_sink(RawCanFrames(
            header=self._header(f"can/{raw.bus}", raw.bus, frames[0].rx_wall_ns),
            bus=raw.bus, interface=self.interface, channel=self.channel,
            frames=tuple(frames)))

    def _publish_results(self, core: RadarCore, results: list[TrackedCycle],
                         processing_ns: int) -> None:
        name = core.sensor.name
        sid = core.sensor.sensor_id
        if processing_ns:
            self._processing_us[sid].append(processing_ns / 1e3)
        for r in results:
            self._last_tracks[sid] = (len(r.tracks), sum(t.confirmed for t in r.tracks))
            if not r.complete:
                self._rl.warning(f"incomplete:{name}", "cycle_incomplete", sensor=name,
                                 closed_by=r.closed_by, meas_counter=r.meas_counter)
            msg = RadarTracks(
                header=self._header(f"tracks/{name}", name, r.stamp_wall_ns),
                sensor=name, mode=r.mode, meas_counter=r.meas_counter, complete=r.complete,
                n_detections=r.n_detections, n_prefiltered=r.n_prefiltered,
                last_frame_mono_ns=r.last_frame_mono_ns, processing_ns=processing_ns,
                tracks=r.tracks,
            )
            self.output.tracks(name, msg)

    def _header(self, stream: str, sensor: str, stamp_ns: int) -> Header:
        seq = self._seq.get(stream, 0)
        self._seq[stream] = seq + 1
        return Header(seq=seq, source=f"radar/{sensor}", stamp_ns=stamp_ns,
                      pub_mono_ns=mono_ns())

    # -- writing ------------------------------------------------------------------------

    def _send_frames(self, frames: list[RadarFrame]) -> int:
        """Write frames if the bus is open; returns how many went out."""
        return self.link.send([radar_message(f) for f in frames])

    def on_ego_motion(self, msg: EgoMotion) -> None:
        """EgoMotion from the bus (any thread): forward as 0x300/0x301 when enabled."""
        frames = self.ego.on_motion(msg, wall_ns(), mono_ns())
        if frames and self._send_frames(frames) == len(frames):
            for f in frames:
                found = classify(f.arb_id)
                if found is not None:
                    self.ego_sent[found[1]] += 1

    # -- stats --------------------------------------------------------------------------

    def log_stats(self, mono: int) -> None:
        """One `radar_stats` line per radar, like the camera's and fusion's: totals, and
        rates and processing times since the previous line."""
        for sid, core in self.cores.items():
            cycles0, frames0, at = self._stats_from.get(sid, (0, 0, 0))
            span_s = (mono - at) / NS_PER_S if at else 0.0
            times = self._processing_us[sid]
            tracks, confirmed = self._last_tracks[sid]
            _log.info(kv(
                "radar_stats", sensor=core.sensor.name, cycles=core.cycles_total,
                rate_hz=(core.cycles_total - cycles0) / span_s if span_s else 0.0,
                frames_per_s=(core.frames_total - frames0) / span_s if span_s else 0.0,
                incomplete=core.cycles_incomplete, meas_counter_gaps=core.meas_counter_gaps,
                tracker_resets=core.tracker.resets, tracks_resumed=core.tracker.resumed,
                tracks=tracks, confirmed=confirmed,
                processing_us_p50=statistics.median(times) if times else 0.0,
                processing_us_max=max(times, default=0.0), rejected=core.rejected.total(),
                bus_state=self.bus_state.value, bus_rejected=self.bus_rejected.total(),
                bus_reopens=self.link.reopens))
            self._stats_from[sid] = (core.cycles_total, core.frames_total, mono)
            times.clear()

    # -- status -------------------------------------------------------------------------

    def _housekeeping(self, mono: int, wall: int) -> None:
        self._publish_raw(older_than_mono_ns=mono - _RAW_BATCH_MAX_AGE_NS)
        self.watchdog.feed()
        if self._stats_period_ns and mono >= self._stats_due:
            if self._stats_due:
                self.log_stats(mono)
            else:               # serving from now: the first line counts from here
                self._stats_from = {sid: (c.cycles_total, c.frames_total, mono)
                                    for sid, c in self.cores.items()}
            self._stats_due = mono + self._stats_period_ns
        for core in self.cores.values():
            results = core.poll(mono)
            if results:
                self._publish_results(core, results, 0)
            self._send_frames(core.config_frames(mono))
        self.link.refresh(mono)
        self._status_tick(mono, wall)

    def _status_tick(self, mono: int, wall: int) -> None:
        """Publish each radar's status when it changed or its period elapsed."""
        for sid, core in self.cores.items():
            key = (core.not_ready_reason(self.bus_state, mono), self.bus_state,
                   core.radar_state, core.firmware)
            if key != self._status_key.get(sid) or mono >= self._status_due[sid]:
                self._publish_status(core, mono, wall)

    def _frames_per_s(self, core: RadarCore, mono: int) -> float:
        sid = core.sensor.sensor_id
        frames, at, rate = self._fps_sample.get(sid, (0, mono, 0.0))
        if mono - at >= NS_PER_S // 2:
            rate = (core.frames_total - frames) * NS_PER_S / (mono - at)
            frames, at = core.frames_total, mono
        self._fps_sample[sid] = (frames, at, rate)
        return rate

    def _publish_status(self, core: RadarCore, mono: int, wall: int) -> None:
        sid = core.sensor.sensor_id
        bus = {f"bus:{k}": v for k, v in self.bus_rejected.snapshot().items()}
        ego = {f"ego_motion:{k}": v for k, v in self.ego.rejected.snapshot().items()}
        msg = core.status(
            self._header(f"status/{core.sensor.name}", core.sensor.name, wall),
            self.bus_state, mono, self.interface, self.channel,
            self._frames_per_s(core, mono), self.link.reopens, {**bus, **ego},
            self.ego_sent[sid],
        )
        self._status_key[sid] = (msg.not_ready_reason, self.bus_state, core.radar_state,
                                 core.firmware)
        self._status_due[sid] = mono + self._period_ns
        if msg.ready != self._ready.get(sid):
            _log.info(kv("radar_ready" if msg.ready else "radar_not_ready",
                         sensor=core.sensor.name, reason=msg.not_ready_reason))
            self._ready[sid] = msg.ready
        self.output.status(core.sensor.name, msg)

    def _publish_all_status(self, mono: int, wall: int) -> None:
        for core in self.cores.values():
            self._publish_status(core, mono, wall)
