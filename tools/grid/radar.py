"""The radar in lockstep: the simulated ARS408 (tools/sim/radar_feed.py: the model, the
radar service's own encoder, frames paced at the wire rate) read by the radar service's
own frame path (`RadarShell.receive` and its housekeeping `tick`: classification, the
pure core's assembly, decoding and tracking), on the simulated clock. A SIMULATION of
the sensor and its CAN link.

A cycle's tracks come out as the radar service publishes them, encoded as on the wire;
the shell's own clock readings (processing time, publish time) are the modelled ones.
"""

from collections.abc import Sequence

import msgspec

from aeb_radar_camera.common.config.radar import RadarSettings
from aeb_radar_camera.common.messages import RadarTracks, encode
from aeb_radar_camera.services.radar.ars408 import RadarFrame
from aeb_radar_camera.services.radar.ports import radar_message
from aeb_radar_camera.services.radar.shell import RadarShell
from aeb_radar_camera.tools.grid.clock import Events
from aeb_radar_camera.tools.grid.delays import Delays
from aeb_radar_camera.tools.recording.rerun_radar import Collected
from aeb_radar_camera.tools.sim.radar_feed import RadarFeed
from aeb_radar_camera.tools.sim.scenario import RadarLook
from aeb_radar_camera.tools.sim.world import Body


class LockstepRadar:
    """`settings`: the radar service's (the demo runs its defaults). `cycle()` models and
    sends one cycle, `tick()` keeps the service's house; both return the RadarTracks the
    service published, with the (loop) time each was published."""

    def __init__(self, events: Events, settings: RadarSettings, delays: Delays,
                 look: RadarLook, seed: int) -> None:
        self.events = events
        self.delays = delays
        self._cursor = 0           # the feed's clock (monotonic ns) while it sends a cycle
        self._sent: list[tuple[int, RadarFrame]] = []
        self.feed = RadarFeed(self, look, seed, clock=self._clock, sleep=self._sleep,
                              yield_cpu=lambda: None)
        self._out = Collected()
        self.shell = RadarShell(settings, self._out)
        self.cycles = 0

    # -- the feed's sink and clock --------------------------------------------------------

    def send(self, frames: Sequence[RadarFrame]) -> None:
        self._sent.extend((self._cursor, f) for f in frames)

    def _clock(self) -> int:
        return self._cursor

    def _sleep(self, seconds: float) -> None:
        self._cursor += round(seconds * 1e9)

    # -- the loop's side ------------------------------------------------------------------

    def reset(self, look: RadarLook, seed: int) -> None:
        """A new scene (the runner does the same at each run's start)."""
        self.feed.reset(look, seed)

    def cycle(self, bodies: list[Body], ego_x_m: float, ego_speed_mps: float,
              yaw_rate_dps: float, t_ns: int) -> list[tuple[int, bytes]]:
        """One cycle sent at `t_ns`: each frame received by the radar service a CAN link
        after it was written, and (time, payload) of every RadarTracks published."""
        ev = self.events
        self._cursor = ev.mono_ns(t_ns)
        self.feed.cycle(bodies, ego_x_m, ego_speed_mps, yaw_rate_dps)
        sent, self._sent = self._sent, []
        out: list[tuple[int, bytes]] = []
        for written, frame in sent:
            rx = written - ev.mono_ns(0) + self.delays.can_link_ns
            wall, mono = ev.wall_ns(rx), ev.mono_ns(rx)
            self.shell.receive(radar_message(frame, wall / 1e9), wall, mono)
            out += [(rx + self.delays.radar_ns, self._published(tracks, mono))
                    for tracks in self._out.got]
            self._out.got.clear()
        self.cycles += 1
        return out

    def tick(self, t_ns: int) -> list[tuple[int, bytes]]:
        """The service's housekeeping at `t_ns` (cycles closed by timeout, status)."""
        self.shell.tick(self.events.mono_ns(t_ns), self.events.wall_ns(t_ns))
        out = [(t_ns + self.delays.radar_ns, self._published(tracks, self.events.mono_ns(t_ns)))
               for tracks in self._out.got]
        self._out.got.clear()
        return out

    def _published(self, tracks: RadarTracks, done_mono_ns: int) -> bytes:
        d = self.delays.radar_ns
        return encode(msgspec.structs.replace(
            tracks, processing_ns=d,
            header=msgspec.structs.replace(tracks.header, pub_mono_ns=done_mono_ns + d)))

