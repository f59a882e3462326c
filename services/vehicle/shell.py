"""The vehicle gateway's I/O shell: reads the car's CAN (common/can_link.py: any
python-can bus or a replayed log, reopened with backoff when lost), feeds the core, and
publishes what the core says is due, the status at a fixed period and on change, and a
stats line. The gateway never writes to the car's bus.

One thread does everything: frames are few (a car's chassis bus carries a few thousand a
second, of which the mapped messages are a few hundred) and the messages go out at their
rates from the loop's housekeeping ticks, which come with the first frame a millisecond
after the previous tick: a message goes out within a frame's spacing of its due time.
"""

import logging
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Protocol

import can

from aeb_radar_camera.common.can_link import CanLink
from aeb_radar_camera.common.can_port import CanPort
from aeb_radar_camera.common.clock import NS_PER_S, mono_ns, wall_ns
from aeb_radar_camera.common.config.vehicle import GatewaySettings
from aeb_radar_camera.common.counters import ReasonCounter
from aeb_radar_camera.common.log import RateLimitedLog, kv
from aeb_radar_camera.common.messages.header import Header
from aeb_radar_camera.common.messages.vehicle import DriverInputs, EgoMotion, VehicleStatus
from aeb_radar_camera.common.systemd import Watchdog
from aeb_radar_camera.services.vehicle.core import VehicleCore

SERVICE = "vehicle"
TICK_NS = 1_000_000
_log = logging.getLogger(SERVICE)


class VehicleOutput(Protocol):
    """Where the gateway publishes (Zenoh in production, lists in tests)."""

    def motion(self, msg: EgoMotion) -> None: ...

    def driver(self, msg: DriverInputs) -> None: ...

    def status(self, msg: VehicleStatus) -> None: ...

    def serving(self) -> None:
        """Called once, when the bus first opened: the gateway now serves."""


class VehicleShell:
    """`bus_rejected`: what went wrong on the bus itself (the link's reasons, and
    ``remote_frame``, ``internal_error``), reported in the status under ``bus:``."""

    def __init__(
        self,
        settings: GatewaySettings,
        core: VehicleCore,
        output: VehicleOutput,
        port_factory: Callable[[], CanPort] | None = None,
        watchdog: Watchdog | None = None,
    ) -> None:
        self.settings = settings
        self.core = core
        self.output = output
        self.watchdog = watchdog or Watchdog(env={})
        self.bus_rejected = ReasonCounter()
        self.link = CanLink(settings.can, settings.replay, SERVICE, self, self.bus_rejected,
                            port_factory, self.watchdog, housekeeping_ns=TICK_NS)
        self.dbc = Path(settings.dbc).name
        self._served = False
        self._seq = 0
        self._status_key: tuple[bool, str, object] | None = None
        self._status_due = 0
        self._period_ns = int(settings.status_period_s * NS_PER_S)
        self._stats_period_ns = int(settings.stats_period_s * NS_PER_S)
        self._stats_due = 0
        self._rl = RateLimitedLog(_log)

    def run(self, stop: threading.Event) -> int:
        """Serve until `stop` is set (or a non-looping replay ends with exit_at_end)."""
        if self.link.run(stop):
            self.link.end(mono_ns())
            _log.info(kv("replay_ended", frames=self.core.frames_total))
            self.log_stats()
            if not self.settings.replay.exit_at_end:
                while not self.watchdog.wait(stop, self.settings.status_period_s):
                    self._publish_status(mono_ns(), wall_ns())
            return 0
        self._publish_status(mono_ns(), wall_ns())
        self.log_stats()
        return 0

    # -- the link's handler -------------------------------------------------------------

    def opened(self, mono: int) -> None:
        if not self._served:
            self._served = True
            self.output.serving()

    def receive(self, msg: can.Message, wall: int, mono: int) -> None:
        if not self.link.accept(msg, mono):
            return
        if msg.is_remote_frame:
            self.bus_rejected.add("remote_frame")
            return
        try:
            self.core.on_frame(msg.arbitration_id, bytes(msg.data), msg.is_extended_id,
                               wall, mono)
        except Exception as exc:
            # A bug in one frame's decoding must not stop the vehicle state that the
            # brake decision reads: count it, log it with its frame, go on.
            self.bus_rejected.add("internal_error")
            if self._rl.error("internal", "core_failed", arb_id=hex(msg.arbitration_id),
                              data=bytes(msg.data).hex(), error=repr(exc)):
                _log.exception("core traceback")

    def tick(self, mono: int, wall: int) -> None:
        self.watchdog.feed()
        for _, message in self.core.poll(mono, wall):
            if isinstance(message, EgoMotion):
                self.output.motion(message)
            else:
                self.output.driver(message)
        self.link.refresh(mono)
        self._status_tick(mono, wall)
        if self._stats_period_ns and mono >= self._stats_due:
            if self._stats_due:
                self.log_stats()
            self._stats_due = mono + self._stats_period_ns

    def waiting(self, mono: int, wall: int) -> None:
        self._status_tick(mono, wall)

    def bus_state_changed(self, mono: int) -> None:
        self._publish_status(mono, wall_ns())

    # -- status and stats ---------------------------------------------------------------

    def _status_tick(self, mono: int, wall: int) -> None:
        reason = self.core.not_ready_reason(self.link.bus_state, mono)
        key = (not reason, reason, self.link.bus_state)
        if key != self._status_key or mono >= self._status_due:
            self._publish_status(mono, wall)

    def _publish_status(self, mono: int, wall: int) -> None:
        header = Header(seq=self._seq, source=self.core.source, stamp_ns=wall,
                        pub_mono_ns=mono_ns())
        self._seq += 1
        msg = self.core.status(header, self.link.bus_state, mono, self.link.interface,
                               self.link.channel, self.dbc, self.link.reopens,
                               self.bus_rejected.snapshot())
        if self._status_key is None or msg.ready != self._status_key[0]:
            _log.info(kv("vehicle_ready" if msg.ready else "vehicle_not_ready",
                         gateway=self.settings.name, reason=msg.not_ready_reason))
        self._status_key = (msg.ready, msg.not_ready_reason, msg.bus_state)
        self._status_due = mono + self._period_ns
        self.output.status(msg)

    def log_stats(self) -> None:
        """One `vehicle_stats` line: totals since start."""
        core = self.core
        _log.info(kv("vehicle_stats", gateway=self.settings.name, frames=core.frames_total,
                     decoded=core.frames_decoded,
                     published=",".join(f"{k}:{v}" for k, v in core.published.snapshot().items())
                     or "none",
                     withheld=core.withheld.total(), rejected=core.rejected.total(),
                     bus_rejected=self.bus_rejected.total(), ignored=core.ignored.total(),
                     bus_state=self.link.bus_state.value, bus_reopens=self.link.reopens))
