"""What the harness watches while it injects faults: the brake's status, fusion's
targets and commands, the radar's tracks, the camera's newest frame (from the bus, each
with its receipt time on this host's monotonic clock) and the simulated actuator's
events."""

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from aeb_radar_camera.common.bus import Bus
from aeb_radar_camera.common.command_auth import CommandKey, mac_problem
from aeb_radar_camera.common.keys import (
    BRAKE_STATUS,
    CAMERA_JPEG,
    FUSION_BRAKE_CMD,
    FUSION_TARGETS,
    RADAR_TRACKS,
)
from aeb_radar_camera.common.messages import BrakeCommand, BrakeStatus, RadarTracks, VerifiedTargets
from aeb_radar_camera.common.messages.codec import DecodeError, decode
from aeb_radar_camera.tools.arrivals import Arrivals

T = TypeVar("T")
M = TypeVar("M", BrakeStatus, VerifiedTargets, BrakeCommand, RadarTracks)
HISTORY = 4000


@dataclass(frozen=True)
class Seen(Generic[T]):
    rx_ns: int
    msg: T


class Stream(Generic[T]):
    """A bounded history of received messages, with a wait on a predicate."""

    def __init__(self) -> None:
        self._arrivals: Arrivals[Seen[T]] = Arrivals(keep=HISTORY)

    def add(self, item: Seen[T]) -> None:
        self._arrivals.add(item)

    def mark(self) -> int:
        """A position: `wait` looks only at what arrives after it."""
        return len(self._arrivals)

    def since(self, mark: int) -> list[Seen[T]]:
        return self._arrivals.since(mark)

    def wait(self, pred: Callable[[T], bool], mark: int, timeout_s: float) -> Seen[T] | None:
        """The first message after `mark` for which `pred` holds, or None at the timeout."""
        found = self._arrivals.first(lambda seen: pred(seen.msg), timeout_s, mark)
        return None if found is None else found[1]

    def last(self) -> Seen[T] | None:
        return self._arrivals.last()


class Observer:
    """Subscribes on the harness's own bus session. Status and targets that do not
    come from the stack's own processes (the harness's floods) are not recorded, nor
    commands that do not authenticate with `keys` (fusion's command keys)."""

    def __init__(self, bus: Bus, actuator: Any, keys: Mapping[str, CommandKey],
                 brake_source: str = "brake/main", fusion_instance: str = "primary") -> None:
        self.status: Stream[BrakeStatus] = Stream()
        self.targets: Stream[VerifiedTargets] = Stream()
        self.commands: Stream[BrakeCommand] = Stream()
        self.tracks: Stream[RadarTracks] = Stream()
        self.actuator_events: Stream[Any] = Stream()
        self.frame_payload: bytes | None = None
        self._brake_source = brake_source
        self._fusion_source = f"fusion/{fusion_instance}"
        self._keys = keys
        self._subs = [
            bus.subscribe_raw(BRAKE_STATUS, self._on_status),
            bus.subscribe_raw(FUSION_TARGETS, self._on_targets, instance=fusion_instance),
            bus.subscribe_raw(FUSION_BRAKE_CMD, self._on_command, instance=fusion_instance),
            bus.subscribe_raw(CAMERA_JPEG, self._on_frame, camera="front"),
            bus.subscribe_raw(RADAR_TRACKS, self._on_tracks, sensor="front"),
        ]
        actuator.add_listener(lambda e: self.actuator_events.add(Seen(e.t_ns, e)))
        self.forged_seen = 0      # harness's own publications that came back (ignored)

    def _on_status(self, payload: bytes, key: str, rx_ns: int) -> None:
        self._keep(payload, rx_ns, BrakeStatus, self._brake_source, self.status)

    def _on_targets(self, payload: bytes, key: str, rx_ns: int) -> None:
        self._keep(payload, rx_ns, VerifiedTargets, self._fusion_source, self.targets)

    def _on_command(self, payload: bytes, key: str, rx_ns: int) -> None:
        self._keep(payload, rx_ns, BrakeCommand, self._fusion_source, self.commands,
                   lambda msg: not mac_problem(payload, msg, self._keys))

    def _on_tracks(self, payload: bytes, key: str, rx_ns: int) -> None:
        self._keep(payload, rx_ns, RadarTracks, "radar/front", self.tracks)

    def _keep(self, payload: bytes, rx_ns: int, msg_type: type[M], source: str,
              stream: Stream[M], authentic: Callable[[M], bool] = lambda msg: True) -> None:
        """Into `stream` when it decodes, comes from `source` and is `authentic`; what
        decodes but is not is one of the harness's own floods come back (counted)."""
        try:
            msg = decode(payload, msg_type)
        except DecodeError:
            return
        if msg.header.source != source or not authentic(msg):
            self.forged_seen += 1
            return
        stream.add(Seen(rx_ns, msg))

    def _on_frame(self, payload: bytes, key: str, rx_ns: int) -> None:
        self.frame_payload = payload
