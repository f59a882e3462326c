"""`aeb record --can INTERFACE:CHANNEL[:BUS]`: raw CAN frames read by the recorder itself
(any python-can interface), for a radar service that does not publish them. They are
recorded on the same key and in the same message as the radar's own (`can/<bus>/frames`,
RawCanFrames), in batches of at most `BATCH_S`."""

import logging
import threading
from collections.abc import Callable

import can

from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.keys import RADAR_CAN
from aeb_radar_camera.common.messages import CanFrame, Header, RawCanFrames
from aeb_radar_camera.common.messages import encode as encode_msg
from aeb_radar_camera.common.messages.radar import can_frame

BATCH_S = 0.075
_log = logging.getLogger("record.can")


class CanReader:
    """Reads one python-can bus in a thread; every batch goes to `submit(key, payload,
    receive_wall_ns)`."""

    def __init__(self, bus: can.BusABC, interface: str, channel: str, bus_name: str,
                 vehicle: str, submit: Callable[[str, bytes, int], None]) -> None:
        self.bus = bus
        self.interface = interface
        self.channel = channel
        self.bus_name = bus_name
        self.key = RADAR_CAN.key(vehicle, bus=bus_name)
        self.submit = submit
        self.frames = 0
        self._seq = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="record-can", daemon=True)

    @classmethod
    def from_spec(cls, spec: str, vehicle: str,
                  submit: Callable[[str, bytes, int], None]) -> "CanReader":
        """`INTERFACE:CHANNEL[:BUS]` (bus name default "radar"). Raises ValueError for a
        malformed spec, OSError (python-can's CanError included) when the bus does not
        open."""
        parts = spec.split(":")
        if len(parts) not in (2, 3) or not all(parts):
            raise ValueError(f"--can {spec!r}: expected INTERFACE:CHANNEL[:BUS]")
        interface, channel = parts[0], parts[1]
        try:
            bus = can.Bus(interface=interface, channel=channel)
        except can.CanError as exc:
            raise OSError(f"--can {spec}: {exc}") from exc
        return cls(bus, interface, channel, parts[2] if len(parts) == 3 else "radar",
                   vehicle, submit)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5)
        self.bus.shutdown()

    def _run(self) -> None:
        batch: list[CanFrame] = []
        started = 0
        while not self._stop.is_set():
            try:
                msg = self.bus.recv(BATCH_S)
            except (can.CanError, OSError) as exc:
                _log.warning("CAN read failed: %r", exc)
                self._stop.wait(0.5)
                continue
            mono = mono_ns()
            if msg is not None:
                if not batch:
                    started = mono
                batch.append(can_frame(msg, wall_ns(), mono))
            if batch and (msg is None or mono - started >= BATCH_S * 1e9):
                self._flush(batch)
                batch = []
        if batch:
            self._flush(batch)

    def _flush(self, batch: list[CanFrame]) -> None:
        header = Header(seq=self._seq, source="record/can", stamp_ns=batch[0].rx_wall_ns,
                        pub_mono_ns=mono_ns())
        self._seq += 1
        self.frames += len(batch)
        self.submit(self.key, encode_msg(RawCanFrames(header, self.bus_name, self.interface,
                                                      self.channel, tuple(batch))), wall_ns())
