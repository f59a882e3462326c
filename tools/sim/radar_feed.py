"""The simulated radar on a CAN link: the model's returns as real ARS408 frames, encoded
with the radar service's own encoder, written where the radar service reads.

A SIMULATION of the sensor: the radar service receives the frames exactly as from a real
ARS408 behind a USB-CAN adapter (slcan over a pty: `SlcanSink`), on SocketCAN (vcan0 or
can0: `PythonCanSink`), or through socketcand. It runs unchanged.

Per cycle: status, N general, N quality, N extended (object mode) or status, N general,
N quality (cluster mode); about once a second the radar state (0x201) and firmware
version (0x700), as the real sensor sends them. What the host writes to the radar is
read back off the link (where the sink offers `add_listener`): the ego speed and yaw rate
(0x300 / 0x301, which the radar service forwards from `vehicle/motion`) set the dynamic
property of every return and the 0x201's MotionRxState, as on the real sensor.
"""

import os
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import can

from aeb_radar_camera.common.clock import mono_ns
from aeb_radar_camera.common.realtime import fifo_for
from aeb_radar_camera.services.radar.ars408 import (
    RMS_CODE_VALUES,
    ClusterGeneral,
    ClusterQuality,
    Kind,
    ObjectExtended,
    ObjectGeneral,
    ObjectQuality,
    RadarFrame,
    RadarFrameError,
    RadarStateFrame,
    Version,
    classify,
    cluster_cycle_frames,
    decode,
    encode,
    object_cycle_frames,
)
from aeb_radar_camera.services.radar.ports import radar_frame, radar_message
from aeb_radar_camera.tools.sim.radar_model import RadarModel, RadarReturn, ReceivedMotion
from aeb_radar_camera.tools.sim.scenario import RadarLook
from aeb_radar_camera.tools.sim.world import Body

FIRMWARE = (4, 30, 2)
STATE_PERIOD_S = 1.0
# A classic CAN frame with 8 data bytes takes about 125 bits (with stuffing) on the wire:
# 0.25 ms at the ARS408's 500 kbit/s. The feed spaces a cycle's frames at that rate (in
# small bursts: sleeps are coarse), so the radar service receives them as from a real bus
# rather than all at once.
FRAME_TIME_S = 125 / 500_000
BURST_FRAMES = 4


# After each write: a pseudo-terminal's bytes reach the reader through a kernel worker
# thread with normal scheduling, and if the simulator kept its CPU (modelling the world,
# rendering, logging) the frames would wait for it, a delay a real CAN adapter does not
# add (first burst of a cycle: 0.17 ms -> 0.05 ms to the radar's read). Unix only;
# elsewhere nothing.
_yield_cpu: Callable[[], None] = getattr(os, "sched_yield", lambda: None)


# The radar forgets an ego speed or yaw rate it has not had for this long.
MOTION_TIMEOUT_S = 0.5


class FrameSink(Protocol):
    def send(self, frames: Sequence[RadarFrame]) -> None: ...


@runtime_checkable
class HostFrames(Protocol):
    """A link that also hands over what the host writes to the radar."""

    def add_listener(self, callback: Callable[[RadarFrame], None]) -> None: ...


class PythonCanSink:
    """Frames onto a python-can bus (socketcan vcan0/can0, or any interface)."""

    def __init__(self, bus: can.BusABC) -> None:
        self.bus = bus

    def send(self, frames: Iterable[RadarFrame]) -> None:
        for f in frames:
            self.bus.send(radar_message(f))


class ListeningCanSink(PythonCanSink):
    """A PythonCanSink that also reads what the host writes, through a python-can
    Notifier (its own thread): `stop()` it before shutting the bus down."""

    def __init__(self, bus: can.BusABC) -> None:
        super().__init__(bus)
        self._notifier: can.Notifier | None = None

    def add_listener(self, callback: Callable[[RadarFrame], None]) -> None:
        def on_message(msg: can.Message) -> None:
            callback(radar_frame(msg))

        if self._notifier is None:
            self._notifier = can.Notifier(self.bus, [on_message], timeout=0.1)
        else:
            self._notifier.add_listener(on_message)

    def stop(self) -> None:
        """Stop listening (the bus stays the caller's)."""
        if self._notifier is not None:
            self._notifier.stop()
            self._notifier = None


class HostMotion:
    """The ego speed (0x300) and yaw rate (0x301) the simulated radar has received, with
    when (thread-safe: frames arrive on the link's reader thread). Frames that are not
    the radar's, or do not decode, are counted in `errors` and otherwise ignored."""

    def __init__(self, sensor_id: int = 0, clock: Callable[[], int] = mono_ns,
                 timeout_s: float = MOTION_TIMEOUT_S) -> None:
        self.sensor_id = sensor_id
        self._clock = clock
        self._timeout_ns = int(timeout_s * 1e9)
        self._lock = threading.Lock()
        self._speed: tuple[float, int] | None = None     # (value, mono ns)
        self._yaw: tuple[float, int] | None = None
        self.frames = 0
        self.errors = 0

    def on_frame(self, frame: RadarFrame) -> None:
        found = classify(frame.arb_id)
        if found is None or found[1] != self.sensor_id or found[0].kind not in (
                Kind.SPEED, Kind.YAW_RATE):
            return          # configuration and other traffic: not the motion input
        try:
            record = decode(found[0], frame.data)
        except RadarFrameError:
            with self._lock:
                self.errors += 1
            return
        now = self._clock()
        with self._lock:
            self.frames += 1
            if found[0].kind is Kind.SPEED:
                sign = -1.0 if record.direction == 2 else 0.0 if record.direction == 0 else 1.0
                self._speed = (sign * record.speed_mps, now)
            else:
                self._yaw = (record.yaw_rate_dps, now)

    def received(self) -> ReceivedMotion:
        """What the radar knows now (None where the input is missing or stale)."""
        now = self._clock()
        with self._lock:
            speed, yaw = self._speed, self._yaw
        fresh = [v if v is not None and now - v[1] <= self._timeout_ns else None
                 for v in (speed, yaw)]
        return ReceivedMotion(fresh[0][0] if fresh[0] else None,
                              fresh[1][0] if fresh[1] else None)


def _clamp(v: float, lo: float, hi: float) -> float:
    return min(max(v, lo), hi)


def rms_code(sigma: float) -> int:
    """The ARS408 5-bit code of a standard deviation (the first bound above it)."""
    for code, bound in enumerate(RMS_CODE_VALUES):
        if sigma < bound:
            return code
    return len(RMS_CODE_VALUES) - 1


def _general(r: RadarReturn, lateral_m: float) -> tuple[float, float, float, float, int, float]:
    """A return's general-message fields after its ID, within what the signals carry
    (the lateral distance's range differs between objects and clusters)."""
    return (_clamp(r.x_m, -500.0, 1138.0), _clamp(r.y_m, -lateral_m, lateral_m),
            _clamp(r.vx_mps, -128.0, 127.75), _clamp(r.vy_mps, -64.0, 63.75), r.dyn_prop,
            _clamp(r.rcs_dbsm, -64.0, 63.5))


def _rms_codes(look: RadarLook) -> tuple[int, int, int, int]:
    """The quality message's standard deviations: distance long, lat, velocity long, lat."""
    return (rms_code(look.range_sigma_m), rms_code(look.lateral_sigma_m),
            rms_code(look.velocity_sigma_mps), rms_code(look.velocity_sigma_mps))


def object_frames(returns: Sequence[RadarReturn], meas_counter: int, look: RadarLook,
                  sensor_id: int = 0) -> list[RadarFrame]:
    """One object-mode cycle with quality and extended messages."""
    general, quality, extended = [], [], []
    for r in returns:
        general.append(ObjectGeneral(r.id, *_general(r, 204.6)))
        quality.append(ObjectQuality(r.id, *_rms_codes(look), r.meas_state, r.prob_of_exist))
        extended.append(ObjectExtended(
            r.id, 0.0, 0.0, r.obj_class, _clamp(r.orientation_deg, -180.0, 180.0),
            _clamp(r.length_m, 0.0, 50.0), _clamp(r.width_m, 0.0, 50.0)))
    return object_cycle_frames(general, meas_counter, quality, extended, sensor_id)


def cluster_frames(returns: Sequence[RadarReturn], meas_counter: int, look: RadarLook,
                   sensor_id: int = 0) -> list[RadarFrame]:
    """One cluster-mode cycle with quality messages (all clusters in the near scan)."""
    general, quality = [], []
    for r in returns:
        general.append(ClusterGeneral(r.id, *_general(r, 102.3)))
        quality.append(ClusterQuality(r.id, *_rms_codes(look), 3 if r.source >= 0 else 5, 3, 0))
    return cluster_cycle_frames(general, meas_counter, quality, sensor_id=sensor_id)


def state_frames(look: RadarLook, sensor_id: int = 0, motion_rx_state: int = 0
                 ) -> list[RadarFrame]:
    """0x201 (no error, configuration as simulated, the motion input's state) and 0x700."""
    state = RadarStateFrame(
        nvm_read_ok=1, max_distance_m=196, persistent_error=0, interference=0,
        temperature_error=0, temporary_error=0, voltage_error=0, sensor_id=sensor_id,
        sort_index=1, motion_rx_state=motion_rx_state,
        send_ext_info=int(look.mode == "objects"),
        send_quality=1, output_type=1 if look.mode == "objects" else 2, rcs_threshold=0)
    return [encode(state, sensor_id), encode(Version(*FIRMWARE), sensor_id)]


@dataclass(frozen=True)
class CycleSent:
    meas_counter: int
    first_write_mono_ns: int
    last_write_mono_ns: int     # after the cycle's last frame was written
    n_returns: int


class RadarFeed:
    """The simulated radar: a model, a sink, a cycle counter. `cycle()` is called by the
    simulator's loop every radar period; every cycle sent is remembered (bounded) with
    the monotonic time its last frame was written, the start of the radar-to-brake
    latency chain."""

    def __init__(self, sink: FrameSink, look: RadarLook, seed: int = 0, sensor_id: int = 0,
                 clock: Callable[[], int] = mono_ns, history: int = 10_000,
                 frame_time_s: float = FRAME_TIME_S,
                 sleep: Callable[[float], None] = time.sleep,
                 yield_cpu: Callable[[], None] = _yield_cpu) -> None:
        self.sink = sink
        self.frame_time_s = frame_time_s
        self._sleep = sleep
        self._yield = yield_cpu
        # > 0: each write and its stamp at this SCHED_FIFO priority, above the radar
        # service's (a benchmark's choice): the service, woken by the write on this
        # thread's CPU, would otherwise run first and the stamp come after its work.
        self.write_priority = 0
        self.look = look
        self.sensor_id = sensor_id
        self.model = RadarModel(look, seed)
        self._clock = clock
        self.host = HostMotion(sensor_id, clock)
        if isinstance(sink, HostFrames):
            sink.add_listener(self.host.on_frame)
        self.meas_counter = 0
        self._last_state_ns: int | None = None
        self.sent: deque[CycleSent] = deque(maxlen=history)
        self._lock = threading.Lock()
        self.errors = 0
        # Called on the caller's thread after every cycle with what was sent and its frames
        # (e.g. a benchmark replaying the same frames elsewhere); keep it short.
        self.on_cycle: Callable[[CycleSent, Sequence[RadarFrame]], None] | None = None

    def reset(self, look: RadarLook, seed: int) -> None:
        """A new scene: a fresh model (IDs, ghosts, noise) with the scenario's radar look."""
        self.look = look
        self.model = RadarModel(look, seed)

    def cycle(self, bodies: list[Body], ego_x_m: float, ego_speed_mps: float,
              yaw_rate_dps: float = 0.0) -> CycleSent:
        """Model one cycle (`RadarModel.cycle`: bodies in the vehicle frame, or the world
        frame of a straight road with the ego's x) with the motion the host last sent,
        and write its frames. Raises OSError/can.CanError when the link is gone (the
        caller decides whether that ends the run)."""
        received = self.host.received()
        returns = self.model.cycle(bodies, ego_x_m, ego_speed_mps, yaw_rate_dps, received)
        if self.look.mode == "objects":
            frames = object_frames(returns, self.meas_counter, self.look, self.sensor_id)
        else:
            frames = cluster_frames(returns, self.meas_counter, self.look, self.sensor_id)
        now = self._clock()
        if self._last_state_ns is None or now - self._last_state_ns >= STATE_PERIOD_S * 1e9:
            self._last_state_ns = now
            self.sink.send(state_frames(self.look, self.sensor_id, received.rx_state))
        first = self._clock()
        last = self._send_paced(frames, first)
        sent = CycleSent(self.meas_counter, first, last, len(returns))
        with self._lock:
            self.sent.append(sent)
        self.meas_counter = (self.meas_counter + 1) % 65536
        if self.on_cycle is not None:
            self.on_cycle(sent, frames)
        return sent

    def send_paced(self, frames: Sequence[RadarFrame]) -> tuple[int, int]:
        """Write frames at the bus rate, as a cycle's are; returns the monotonic times
        before the first and after the last write. Raises what the sink raises."""
        first = self._clock()
        return first, self._send_paced(frames, first)

    def _send_paced(self, frames: Sequence[RadarFrame], start_ns: int) -> int:
        """The time right after the last write (before this thread lets others run: the
        reader may well be quicker than this thread's next instruction)."""
        if self.frame_time_s <= 0:
            return self._write(frames)
        last = start_ns
        for i in range(0, len(frames), BURST_FRAMES):
            due = start_ns + i * self.frame_time_s * 1e9
            wait = (due - self._clock()) / 1e9
            if wait > 0:
                self._sleep(wait)
            last = self._write(frames[i:i + BURST_FRAMES])
        return last

    def _write(self, frames: Sequence[RadarFrame]) -> int:
        """Write, stamp, let the reader run; the stamp."""
        with fifo_for(self.write_priority):
            self.sink.send(frames)
            stamp = self._clock()
        self._yield()
        return stamp

    def cycles(self) -> list[CycleSent]:
        """The cycles sent so far (a copy: the loop thread keeps appending)."""
        with self._lock:
            return list(self.sent)
