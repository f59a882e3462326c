"""The radar's decoding and tracking over the raw CAN frames of a recording, offline.

The recorded frames (`can/<bus>/frames`, RawCanFrames) go through the radar shell's own
frame path (`RadarShell.receive`: classification, each radar's pure core) with the
times the live service had (each frame's interface timestamp and host receive times),
and its housekeeping (`RadarShell.tick`: cycles closed by timeout) on the live loop's
schedule: every 10 ms of frames, and after 50 ms without one. No port is opened and
nothing is written to a bus; the shell's own clock readings (`processing_ns`, the
header's publish time) are replaced by the recorded times, so that the outputs are the
same bytes on every run.

What limits exactness: the housekeeping ticks of the live loop are not recorded (a
cycle closed by timeout may close a little earlier or later: the same tracks, another
`closed_by`), and frames the radar service received but could not publish (its link
congested: the key drops rather than waits) are missing from the recording, which the
batches' sequence numbers show.
"""

from collections.abc import Iterator

import msgspec

from aeb_radar_camera.common.config.radar import RadarSettings
from aeb_radar_camera.common.keys import RADAR_CAN, RADAR_TRACKS
from aeb_radar_camera.common.messages import (
    DecodeError,
    RadarStatus,
    RadarTracks,
    RawCanFrames,
    decode,
)
from aeb_radar_camera.common.messages.radar import can_message
from aeb_radar_camera.services.radar.shell import HOUSEKEEPING_NS, RECEIVE_TIMEOUT_NS, RadarShell
from aeb_radar_camera.tools.recording.compare import Comparison
from aeb_radar_camera.tools.recording.reader import Recording


class Collected:
    """The shell's output (RadarOutput): the tracks it publishes, in order (status is
    not kept)."""

    def __init__(self) -> None:
        self.got: list[RadarTracks] = []

    def tracks(self, sensor: str, msg: RadarTracks) -> None:
        self.got.append(msg)

    def status(self, sensor: str, msg: RadarStatus) -> None:
        pass

    def serving(self) -> None:
        pass


class RadarRerun:
    def __init__(self, settings: RadarSettings, vehicle: str = "ego",
                 exact: bool = False) -> None:
        self.settings = settings
        self.vehicle = vehicle
        self.can_topic = RADAR_CAN.key(vehicle, bus=settings.raw_can.bus)
        self.comparison = Comparison(exact=exact)
        self.frames = 0
        self.cycles = 0
        self.batches_missed = 0
        self.span_s = 0.0

    def run(self, recording: Recording, start_ns: int | None = None, end_ns: int | None = None,
            compare: bool = False) -> Iterator[tuple[RadarTracks | None, RadarTracks, int]]:
        """(recorded cycle or None, re-run cycle, log time) for every cycle."""
        recorded: dict[tuple[str, int], RadarTracks] = {}
        if compare:
            topics = [RADAR_TRACKS.key(self.vehicle, sensor=s.name)
                      for s in self.settings.sensors]
            for rec in recording.records(topics, start_ns, end_ns):
                try:
                    t = decode(rec.data, RadarTracks)
                except DecodeError:
                    continue
                recorded[(t.sensor, t.header.stamp_ns)] = t
        out = Collected()
        shell = RadarShell(self.settings, out)
        next_tick = 0
        last_mono: int | None = None
        last_seq: int | None = None
        first_log = last_log = None
        for rec in recording.records([self.can_topic], start_ns, end_ns):
            try:
                batch = decode(rec.data, RawCanFrames)
            except DecodeError:
                continue
            first_log = rec.log_time_ns if first_log is None else first_log
            last_log = rec.log_time_ns
            if last_seq is not None and batch.header.seq > last_seq + 1:
                self.batches_missed += batch.header.seq - last_seq - 1
            last_seq = batch.header.seq
            for f in batch.frames:
                # The live loop woke every 50 ms without a frame, and kept house then.
                while last_mono is not None and f.rx_mono_ns - last_mono > RECEIVE_TIMEOUT_NS:
                    last_mono += RECEIVE_TIMEOUT_NS
                    if last_mono >= next_tick:
                        shell.tick(last_mono, f.rx_wall_ns)
                        next_tick = last_mono + HOUSEKEEPING_NS
                shell.receive(can_message(f), f.rx_wall_ns, f.rx_mono_ns)
                self.frames += 1
                last_mono = f.rx_mono_ns
                if f.rx_mono_ns >= next_tick:
                    shell.tick(f.rx_mono_ns, f.rx_wall_ns)
                    next_tick = f.rx_mono_ns + HOUSEKEEPING_NS
                yield from self._drain(out, recorded, rec.log_time_ns)
        # A cycle still open at the recording's end is not flushed: live, it went on.
        self.span_s = ((last_log or 0) - (first_log or 0)) / 1e9
        self.comparison.recorded_only = len(recorded)

    def _drain(self, out: Collected, recorded: dict[tuple[str, int], RadarTracks],
               log_ns: int) -> Iterator[tuple[RadarTracks | None, RadarTracks, int]]:
        for msg in out.got:
            msg = normalised(msg)
            self.cycles += 1
            mine = recorded.pop((msg.sensor, msg.header.stamp_ns), None)
            self.comparison.add_tracks(msg.header.seq, msg.header.stamp_ns, mine, msg)
            yield mine, msg, log_ns
        out.got.clear()


def normalised(msg: RadarTracks) -> RadarTracks:
    """The shell's clock readings replaced: processing time 0, published at the cycle's
    last frame."""
    return msgspec.structs.replace(
        msg, processing_ns=0,
        header=msgspec.structs.replace(msg.header, pub_mono_ns=msg.last_frame_mono_ns))
