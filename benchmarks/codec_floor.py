"""The least work a Python implementation of the chain's three services must do with the
project's frames and messages, for the latency benchmark's "codec floor"
(`floor_relay --work codec`): no tracking, no
verification, no decision rules, no validation; only reading the radar's frames and the
project's messages and writing the next ones.

- radar: every slcan line of the cycle parsed (ID, DLC, data bytes), every object general
  frame (0x60B) decoded with the ARS408 codec, one RadarTrack per object (range and range
  rate from the frame's position and velocity) and the RadarTracks encoded;
- fusion: the RadarTracks decoded, the nearest track ahead picked, a BrakeCommand about it
  (decision NONE) encoded;
- brake: the BrakeCommand decoded and its actuator line built (CRC included).

Pure but for `clock`, which stamps a message's `pub_mono_ns` once its content is built,
as the services do (its encoding and put are then in the hop that follows). Raises what
the codecs raise on bad input (`FrameError`, `DecodeError`): the floor is fed by the
benchmark only.
"""

import math
from collections.abc import Callable

from common.messages import (
    BrakeCommand,
    Decision,
    Header,
    OutputMode,
    RadarTrack,
    RadarTracks,
    VerifierStatus,
    decode,
    encode,
)
from services.brake.protocol import SEQ_MODULO, HostMode, command_line, level_to_wire
from services.radar.ars408 import Kind, ObjectGeneral, classify
from services.radar.ars408 import decode as decode_record
from tools.sim.can_links import parse_slcan_frame

COMMAND_TTL_MS = 250


class RadarCodec:
    """Collects a cycle's objects from its lines; `tracks` encodes them."""

    def __init__(self, sensor: str) -> None:
        self.sensor = sensor
        self.source = f"radar/{sensor}"
        self._objects: list[ObjectGeneral] = []
        self._seq = 0

    def line(self, line: bytes) -> None:
        """One slcan line of the cycle (a status frame starts a new one; lines that are
        not ARS408 frames are not the cycle's)."""
        frame = parse_slcan_frame(line.decode())
        found = classify(frame.arb_id) if frame is not None else None
        if frame is None or found is None:
            return
        spec = found[0]
        if spec.kind is Kind.OBJECT_GENERAL:
            self._objects.append(decode_record(spec, frame.data))
        elif spec.kind is Kind.OBJECT_STATUS:
            self._objects = []

    def tracks(self, meas_counter: int, last_frame_mono_ns: int, now_wall_ns: int,
               clock: Callable[[], int]) -> tuple[bytes, int]:
        """The cycle's RadarTracks, encoded, and its `pub_mono_ns`; starts the next
        cycle."""
        self._seq += 1
        tracks = tuple(_track(o) for o in self._objects)
        self._objects = []
        now_mono_ns = clock()
        return encode(RadarTracks(
            header=Header(seq=self._seq, source=self.source, stamp_ns=now_wall_ns,
                          pub_mono_ns=now_mono_ns),
            sensor=self.sensor, mode=OutputMode.OBJECTS, meas_counter=meas_counter,
            complete=True, n_detections=len(tracks), n_prefiltered=len(tracks),
            last_frame_mono_ns=last_frame_mono_ns,
            processing_ns=now_mono_ns - last_frame_mono_ns, tracks=tracks)), now_mono_ns


def _track(o: ObjectGeneral) -> RadarTrack:
    r = math.hypot(o.dist_long_m, o.dist_lat_m)
    rate = (o.dist_long_m * o.vrel_long_mps + o.dist_lat_m * o.vrel_lat_mps) / r if r else 0.0
    return RadarTrack(track_id=o.id, x_m=o.dist_long_m, y_m=o.dist_lat_m,
                      vx_mps=o.vrel_long_mps, vy_mps=o.vrel_lat_mps, range_m=r,
                      range_rate_mps=rate, rcs_dbsm=o.rcs_dbsm, confirmed=True, hits=1,
                      misses=0, x_var_m2=0.0, y_var_m2=0.0, radar_object_id=o.id,
                      dyn_prop=o.dyn_prop)


class FusionCodec:
    """RadarTracks in, a BrakeCommand about the nearest track ahead out."""

    def __init__(self, instance: str) -> None:
        self.instance = instance
        self.source = f"fusion/{instance}"
        self._seq = 0

    def command(self, payload: bytes | memoryview,
                clock: Callable[[], int]) -> tuple[bytes, int]:
        """The BrakeCommand, encoded, and its `pub_mono_ns`."""
        tracks = decode(payload, RadarTracks)
        ahead = [t for t in tracks.tracks if t.x_m > 0.0]
        near = min(ahead, key=lambda t: t.range_m) if ahead else None
        ttc = (near.range_m / -near.range_rate_mps
               if near is not None and near.range_rate_mps < 0.0 else None)
        self._seq += 1
        now_mono_ns = clock()
        return encode(BrakeCommand(
            header=Header(seq=self._seq, source=self.source, stamp_ns=tracks.header.stamp_ns,
                          pub_mono_ns=now_mono_ns),
            instance=self.instance, decision=Decision.NONE, brake_level_pct=0.0,
            verifier_status=VerifierStatus.OK, held=False,
            track_id=near.track_id if near is not None else -1,
            range_m=near.range_m if near is not None else None, ttc_s=ttc, reason="",
            radar_seq=tracks.header.seq,
            radar_last_frame_mono_ns=tracks.last_frame_mono_ns)), now_mono_ns


def brake_line(payload: bytes | memoryview) -> bytes:
    """A BrakeCommand's actuator line."""
    cmd = decode(payload, BrakeCommand)
    mode = HostMode.BRAKING if cmd.decision is Decision.BRAKE else HostMode.ARMED
    return command_line(cmd.header.seq % SEQ_MODULO, level_to_wire(cmd.brake_level_pct),
                        COMMAND_TTL_MS, mode)
