"""Payloads of the two fusion instances into the comparator (live, from a recording, or
in the demo)."""

import threading

from aeb_radar_camera.common.keys import FUSION_BRAKE_CMD, FUSION_TARGETS
from aeb_radar_camera.common.messages import BrakeCommand, DecodeError, VerifiedTargets, decode
from aeb_radar_camera.tools.ab.compare import Comparator


class Feeder:
    """Decodes payloads and feeds the comparator; counts what does not decode."""

    def __init__(self, comparator: Comparator) -> None:
        self.comparator = comparator
        self.undecodable = 0
        self._lock = threading.Lock()

    def feed(self, spec_name: str, payload: bytes) -> None:
        with self._lock:
            try:
                if spec_name == FUSION_TARGETS.name:
                    self.comparator.add_targets(decode(payload, VerifiedTargets))
                elif spec_name == FUSION_BRAKE_CMD.name:
                    self.comparator.add_command(decode(payload, BrakeCommand))
            except DecodeError:
                self.undecodable += 1
