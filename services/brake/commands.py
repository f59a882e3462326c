"""Validation of incoming BrakeCommands: instance, schema, fields, sequence, age. Pure."""

import enum
import math
from dataclasses import dataclass

from common.config.brake import AgeClock
from common.messages import BrakeCommand, Decision, DecodeError, decode


class Rejection(enum.Enum):
    """Why a command was not used. The values are the keys of BrakeStatus.rejected."""

    WRONG_INSTANCE = "wrong_instance"  # another fusion instance (key or payload)
    MALFORMED = "malformed"            # not a BrakeCommand of this schema version
    INVALID = "invalid"                # decodes, but breaks the contract (level range, ...)
    OLD_SEQUENCE = "old_sequence"      # sequence number below the last accepted one
    DUPLICATE = "duplicate"            # sequence number equal to the last accepted one
    TOO_OLD = "too_old"                # age above max_age_ms
    FUTURE_STAMP = "future_stamp"      # stamped in the future: clocks not comparable


@dataclass(frozen=True, slots=True)
class Accepted:
    cmd: BrakeCommand
    gap: int          # commands missing since the previous accepted one (0 when contiguous)
    restart: bool     # a new stream after silence: the sequence baseline was reset


class CommandValidator:
    """Decides whether one received payload is a usable command.

    `expected_key` is the concrete key of the configured instance: anything published on
    another key is WRONG_INSTANCE before any decoding. The sequence must increase; after
    a silence longer than the deadline (`stream_alive` false) any sequence starts a new
    stream, so that a restarted fusion process (sequence from 0) is followed again.
    """

    def __init__(
        self,
        expected_key: str,
        instance: str,
        age_clock: AgeClock,
        max_age_ns: int,
        max_future_ns: int,
    ) -> None:
        self.expected_key = expected_key
        self.instance = instance
        self.age_clock = age_clock
        self.max_age_ns = max_age_ns
        self.max_future_ns = max_future_ns
        self.last_seq: int | None = None

    def age_ns(self, cmd: BrakeCommand, rx_mono_ns: int, rx_wall_ns: int) -> int:
        """Monotonic: transport age (same host only). Wall: age since the radar cycle."""
        if self.age_clock is AgeClock.MONOTONIC:
            return rx_mono_ns - cmd.header.pub_mono_ns
        return rx_wall_ns - cmd.header.stamp_ns

    def check(
        self, payload: bytes, key: str, rx_mono_ns: int, rx_wall_ns: int, stream_alive: bool
    ) -> Accepted | Rejection:
        if key != self.expected_key:
            return Rejection.WRONG_INSTANCE
        try:
            cmd = decode(payload, BrakeCommand)
        except DecodeError:
            return Rejection.MALFORMED
        if cmd.instance != self.instance:
            return Rejection.WRONG_INSTANCE
        level = cmd.brake_level_pct
        if (not math.isfinite(level) or not 0.0 <= level <= 100.0
                or (level > 0.0 and cmd.decision is not Decision.BRAKE)
                or cmd.header.seq < 0):
            return Rejection.INVALID
        age = self.age_ns(cmd, rx_mono_ns, rx_wall_ns)
        if age > self.max_age_ns:
            return Rejection.TOO_OLD
        if age < -self.max_future_ns:
            return Rejection.FUTURE_STAMP
        seq = cmd.header.seq
        last = self.last_seq
        restart = False
        gap = 0
        if last is not None:
            if stream_alive:
                if seq == last:
                    return Rejection.DUPLICATE
                if seq < last:
                    return Rejection.OLD_SEQUENCE
                gap = seq - last - 1
            else:
                restart = seq <= last
                gap = 0 if restart else seq - last - 1
        self.last_seq = seq
        return Accepted(cmd, gap, restart)
