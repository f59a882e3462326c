"""The brake in lockstep: the brake service's pure core (services/brake/core.py) and the
simulated actuator (tools/sim/actuator.py: first-order position, its own watchdog) on
the actuator protocol's lines, on the simulated clock. A SIMULATION of the actuator and
its serial link.

As the brake service's shell does: each signed command goes to `BrakeCore.on_command`
with its receive times, every line the core sends is encoded (services/brake/protocol.py)
and read by the actuator a serial hop later, its acknowledgements and fault lines are
split into lines (the protocol's LineReader) and go to `BrakeCore.on_rx`, and the core's
timer runs at its due times (at the latest every TIMER_PERIOD_S).
"""

from collections.abc import Mapping

from aeb_radar_camera.common.command_auth import CommandKey
from aeb_radar_camera.common.config.brake import BrakeSettings
from aeb_radar_camera.common.keys import FUSION_BRAKE_CMD
from aeb_radar_camera.services.brake.core import BrakeCore, CoreView, Outgoing
from aeb_radar_camera.services.brake.protocol import LineReader, encode
from aeb_radar_camera.services.brake.shell import MIN_WAIT_NS, TIMER_PERIOD_S
from aeb_radar_camera.tools.grid.clock import Events
from aeb_radar_camera.tools.grid.delays import Delays
from aeb_radar_camera.tools.sim.actuator import SimActuator
from aeb_radar_camera.tools.sim.runner import SimActuatorView

_TIMER_PERIOD_NS = round(TIMER_PERIOD_S * 1e9)


class LockstepBrake:
    """`settings` and `keys`: the brake service's (the instance it follows and its
    command keys); `vehicle`: the key's vehicle."""

    def __init__(self, events: Events, settings: BrakeSettings,
                 keys: Mapping[str, CommandKey], delays: Delays, vehicle: str = "ego") -> None:
        self.events = events
        self.delays = delays
        self.key = FUSION_BRAKE_CMD.key(vehicle, instance=settings.instance)
        self.core = BrakeCore(settings, self.key, events.mono_ns(), keys)
        self.actuator, self._endpoint = SimActuator.in_memory(events.mono_ns)
        self.view = SimActuatorView(self.actuator)
        self._reader = LineReader()
        self._tick_at: int | None = None
        self.lines = 0

    def close(self) -> None:
        self.actuator.stop()

    # -- events -------------------------------------------------------------------------

    def connect(self, t_ns: int) -> None:
        """The serial port opened."""
        self._send(self.core.on_link(True, self.events.mono_ns(t_ns)), t_ns)

    def on_command(self, payload: bytes, t_ns: int) -> CoreView:
        """A command received at `t_ns`; the core's view after it."""
        ev = self.events
        self._send(self.core.on_command(payload, self.key, ev.mono_ns(t_ns), ev.wall_ns(t_ns)),
                   t_ns)
        return self.core.view()

    def step(self, t_ns: int) -> None:
        """The actuator's own housekeeping (its watchdog) at `t_ns`, and what it wrote."""
        self.actuator.receive(b"", self.events.mono_ns(t_ns))
        self._from_actuator(t_ns)

    def position_pct(self, t_ns: int) -> float:
        return float(self.actuator.position_pct(self.events.mono_ns(t_ns)))

    # -- lines --------------------------------------------------------------------------

    def _send(self, out: Outgoing | None, t_ns: int) -> None:
        if out is not None:
            line = encode(out.frame)
            self.lines += 1
            self.events.at(t_ns + self.delays.brake_ns + self.delays.serial_ns,
                           lambda t: self._to_actuator(line, t))
        self._schedule_tick(t_ns)

    def _to_actuator(self, line: bytes, t_ns: int) -> None:
        self.actuator.receive(line, self.events.mono_ns(t_ns))
        self._from_actuator(t_ns)

    def _from_actuator(self, t_ns: int) -> None:
        data = self._endpoint.take()
        if data:
            self.events.at(t_ns + self.delays.serial_ns, lambda t: self._to_host(data, t))

    def _to_host(self, data: bytes, t_ns: int) -> None:
        now = self.events.mono_ns(t_ns)
        for item in self._reader.feed(data):
            self._send(self.core.on_rx(item, now), t_ns)

    # -- the core's timer ------------------------------------------------------------------

    def _schedule_tick(self, t_ns: int) -> None:
        now = self.events.mono_ns(t_ns)
        due = self.core.next_due_ns(now)
        wake = now + _TIMER_PERIOD_NS if due is None else min(due, now + _TIMER_PERIOD_NS)
        at = max(wake, now + MIN_WAIT_NS) - self.events.mono_ns(0)
        if self._tick_at is None or at < self._tick_at:
            self._tick_at = at
            self.events.at(at, self._tick)

    def _tick(self, t_ns: int) -> None:
        if t_ns != self._tick_at:
            return              # superseded by an earlier one
        self._tick_at = None
        self._send(self.core.on_tick(self.events.mono_ns(t_ns)), t_ns)
