"""The latency benchmark's floor: the radar-to-brake chain's transports with no work in
between. Three relay processes, one per service of the chain:

    python -m benchmarks.floor_relay can    --connect EP --channel /dev/pts/N
    python -m benchmarks.floor_relay hop    --connect EP
    python -m benchmarks.floor_relay serial --connect EP --port PATH

- `can` reads the slcan pty raw (one read per wake-up, no python-can, no decoding but
  the status frame's object count and cycle counter, to know when a cycle's last frame
  is in) and publishes a payload as large as the RadarTracks the radar would publish for
  that many objects, on `radar/front/tracks` with that key's QoS;
- `hop` forwards every such payload as a BrakeCommand-sized payload on
  `fusion/primary/brake_cmd` (that key's QoS);
- `serial` writes a brake command line to its serial port for every payload (the brake
  service's write path: straight to the fd), then prints the chain's stamps on stdout.

Every key is under another vehicle id (`--vehicle`, default `floor`) so that nothing of
the stack sees these payloads. Payloads are stamps (monotonic ns, little-endian int64)
padded to size: `counter, can_rx, can_pub[, hop_rx, hop_pub]`. The `serial` relay prints
one line per cycle: `counter can_rx can_pub hop_rx hop_pub serial_rx serial_written`.
Each relay declares `health/floor-<role>/main` once it serves and stops on SIGTERM.
"""

import argparse
import os
import select
import struct
import sys
import threading
from collections.abc import Callable

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.config.realtime import RealtimeSettings
from aeb_radar_camera.common.keys import FUSION_BRAKE_CMD, RADAR_TRACKS
from aeb_radar_camera.common.log import setup_logging
from aeb_radar_camera.common.messages import (
    BrakeCommand,
    Decision,
    Header,
    OutputMode,
    RadarTrack,
    RadarTracks,
    VerifierStatus,
    encode,
)
from aeb_radar_camera.common.realtime import ThreadRealtime
from aeb_radar_camera.common.service import stop_event_on_signals
from aeb_radar_camera.services.brake.protocol import HostMode, command_line

VEHICLE = "floor"
SENSOR = "front"
INSTANCE = "primary"
_STAMPS = struct.Struct("<qqq")          # counter, can_rx, can_pub
_HOP_STAMPS = struct.Struct("<qq")       # hop_rx, hop_pub
OBJECT_STATUS = b"t60A"                 # ARS408 object list status, sensor 0
FRAMES_PER_OBJECT = 3                   # general, quality, extended (the simulated radar)
MAX_OBJECTS = 255


def _track(i: int) -> RadarTrack:
    return RadarTrack(track_id=i, x_m=12.345, y_m=-0.678, vx_mps=-5.432, vy_mps=0.123,
                      range_m=12.37, range_rate_mps=-5.41, rcs_dbsm=7.5, confirmed=True,
                      hits=12, misses=0, x_var_m2=0.0912, y_var_m2=0.2317,
                      radar_object_id=i, dyn_prop=0, obj_class=1)


def tracks_size(n_tracks: int) -> int:
    """Bytes of a RadarTracks with `n_tracks` tracks (typical values)."""
    now = mono_ns()
    return len(encode(RadarTracks(
        header=Header(seq=123456, source="radar/front", stamp_ns=wall_ns(), pub_mono_ns=now),
        sensor=SENSOR, mode=OutputMode.OBJECTS, meas_counter=12345, complete=True,
        n_detections=n_tracks, n_prefiltered=n_tracks, last_frame_mono_ns=now,
        processing_ns=123456, tracks=tuple(_track(i) for i in range(n_tracks)))))


def command_size() -> int:
    """Bytes of a typical BrakeCommand (a BRAKE with its deciding track)."""
    now = mono_ns()
    return len(encode(BrakeCommand(
        header=Header(seq=123456, source="fusion/primary", stamp_ns=wall_ns(),
                      pub_mono_ns=now),
        instance=INSTANCE, decision=Decision.BRAKE, brake_level_pct=100.0,
        verifier_status=VerifierStatus.OK, held=False, track_id=12, range_m=12.37,
        ttc_s=2.28, reason="verified, in path, TTC_eff 1.28 s < 2.5 s", radar_seq=123456,
        radar_last_frame_mono_ns=now)))


def pad(head: bytes, size: int) -> bytes:
    return head + bytes(max(0, size - len(head)))


class CycleEnd:
    """Knows when an object-mode cycle's last frame is in: the status frame announces N
    objects, then N * `frames_per_object` frames follow. Pure (lines in, events out)."""

    def __init__(self, frames_per_object: int = FRAMES_PER_OBJECT) -> None:
        self.frames_per_object = frames_per_object
        self._left: int | None = None
        self.counter = 0
        self.objects = 0

    def line(self, line: bytes) -> bool:
        """One slcan line without its CR; True when it completed a cycle."""
        if line[:4] == OBJECT_STATUS and len(line) >= 11:
            try:
                self.objects = int(line[5:7], 16)
                self.counter = int(line[7:11], 16)
            except ValueError:
                self._left = None
                return False
            self._left = self.frames_per_object * self.objects
        elif self._left is not None and line[:1] == b"t":
            self._left -= 1
        else:
            return False
        if self._left == 0:
            self._left = None
            return True
        return False


def run_can(bus: Bus, channel: str, stop: threading.Event) -> None:
    pub = bus.publisher(RADAR_TRACKS, sensor=SENSOR)
    sizes = [tracks_size(n) for n in range(MAX_OBJECTS + 1)]

    def publish(end: CycleEnd, rx: int) -> None:
        head = _STAMPS.pack(end.counter, rx, mono_ns())
        pub.put_bytes(pad(head, sizes[min(end.objects, MAX_OBJECTS)]))

    fd = os.open(channel, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        os.write(fd, b"O\r")            # as python-can opens the channel: the link sees it
        bus.declare_health("floor-can", "main")
        end = CycleEnd()
        buf = b""
        while not stop.is_set():
            ready, _, _ = select.select([fd], [], [], 0.2)
            if not ready:
                continue
            try:
                chunk = os.read(fd, 4096)
            except BlockingIOError:
                continue
            rx = mono_ns()
            *lines, buf = (buf + chunk).split(b"\r")
            for line in lines:
                if end.line(line):
                    publish(end, rx)
    finally:
        os.close(fd)


def run_hop(bus: Bus, stop: threading.Event) -> None:
    pub = bus.publisher(FUSION_BRAKE_CMD, instance=INSTANCE)
    size = command_size()

    def forward(payload: bytes, key: str, rx: int) -> None:
        head = payload[:_STAMPS.size] + _HOP_STAMPS.pack(rx, mono_ns())
        pub.put_bytes(pad(head, size))

    bus.subscribe_raw(RADAR_TRACKS, forward, sensor=SENSOR)
    bus.declare_health("floor-hop", "main")
    stop.wait()


def run_serial(bus: Bus, port: str, stop: threading.Event,
               report: Callable[[str], None]) -> None:
    import serial

    ser = serial.Serial(port, 115200, timeout=0.05, write_timeout=0.02)
    line = command_line(123456, 100, 250, HostMode.BRAKING)
    n = _STAMPS.size + _HOP_STAMPS.size

    def write(payload: bytes, key: str, rx: int) -> None:
        os.write(ser.fd, line)
        written = mono_ns()
        stamps = struct.unpack("<qqqqq", payload[:n])
        report(" ".join(str(v) for v in (*stamps, rx, written)))

    bus.subscribe_raw(FUSION_BRAKE_CMD, write, instance=INSTANCE)
    bus.declare_health("floor-serial", "main")
    stop.wait()
    ser.close()


def _print_line(text: str) -> None:
    sys.stdout.write(text + "\n")
    sys.stdout.flush()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.floor_relay",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("role", choices=("can", "hop", "serial"))
    parser.add_argument("--connect", required=True, help="the router's endpoint")
    parser.add_argument("--vehicle", default=VEHICLE)
    parser.add_argument("--channel", help="can: the slcan pty to read")
    parser.add_argument("--port", help="serial: the serial port to write")
    parser.add_argument("--realtime-priority", type=int, default=0, choices=range(100),
                        metavar="0..99", help="SCHED_FIFO for every thread (as the stack's)")
    args = parser.parse_args(argv)
    if args.role == "can" and not args.channel:
        parser.error("can needs --channel")
    if args.role == "serial" and not args.port:
        parser.error("serial needs --port")
    stop = stop_event_on_signals()
    # as the router: every thread of a relay is on its path, and inherits the policy
    ThreadRealtime(RealtimeSettings(priority=args.realtime_priority),
                   setup_logging("floor_relay"), f"floor relay {args.role}").ensure()
    settings = ZenohSettings(mode=ZenohMode.CLIENT, connect=(args.connect,))
    with Bus.open(settings, args.vehicle, f"floor/{args.role}") as bus:
        if args.role == "can":
            run_can(bus, args.channel, stop)
        elif args.role == "hop":
            run_hop(bus, stop)
        else:
            run_serial(bus, args.port, stop, _print_line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
