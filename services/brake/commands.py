"""Validation of incoming BrakeCommands: instance, schema, MAC, fields, age, session and
sequence. Pure."""

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass

from common.command_auth import CommandKey, mac_problem
from common.config.brake import AgeClock
from common.messages import BrakeCommand, Decision, DecodeError, decode

JUMP_SLACK = 16   # sequence numbers an authenticated command may skip beyond the rate bound


class Rejection(enum.Enum):
    """Why a command was not used. The values are the keys of BrakeStatus.rejected."""

    WRONG_INSTANCE = "wrong_instance"  # another fusion instance (key or payload)
    MALFORMED = "malformed"            # not a BrakeCommand of this schema version
    UNAUTHENTICATED = "unauthenticated"  # no MAC
    UNKNOWN_KEY = "unknown_key"        # a MAC with a key id the brake does not hold
    BAD_MAC = "bad_mac"                # the MAC does not match the payload
    INVALID = "invalid"                # decodes, but breaks the contract (level range, ...)
    OLD_SEQUENCE = "old_sequence"      # sequence number below the last accepted one
    DUPLICATE = "duplicate"            # sequence number equal to the last accepted one
    TOO_OLD = "too_old"                # age above max_age_ms
    FUTURE_STAMP = "future_stamp"      # stamped in the future: clocks not comparable
    SEQ_JUMP = "seq_jump"              # sequence ahead of what the time since allows
    OTHER_SESSION = "other_session"    # another session of the key while one is live


@dataclass(frozen=True, slots=True)
class Accepted:
    cmd: BrakeCommand
    gap: int          # commands missing since the previous accepted one (0 when contiguous)
    restart: bool     # a new session (fusion restarted): the sequence baseline was reset
    data_age_ns: int  # age of the radar data the command was built from


class CommandValidator:
    """Decides whether one received payload is a usable command.

    `expected_key` is the concrete key of the configured instance: anything published on
    another key is WRONG_INSTANCE before any decoding. A command must carry a valid MAC
    of one of `keys` (the instance's, by key id), be fresh, and continue the session it
    belongs to: within a session the sequence must increase, by at most JUMP_SLACK plus
    `max_rate_hz` times the time since the last accepted command. Another session of the
    key (a restarted fusion) is taken up only while the current one is silent
    (`stream_alive` false); its first command resets the sequence baseline. Nothing that
    is rejected changes this state.
    """

    def __init__(
        self,
        expected_key: str,
        instance: str,
        age_clock: AgeClock,
        max_age_ns: int,
        max_future_ns: int,
        keys: Mapping[str, CommandKey],
        max_rate_hz: float = 200.0,
    ) -> None:
        self.expected_key = expected_key
        self.instance = instance
        self.age_clock = age_clock
        self.max_age_ns = max_age_ns
        self.max_future_ns = max_future_ns
        self.keys = dict(keys)
        self.max_rate_per_ns = max_rate_hz / 1e9
        self.last_seq: int | None = None
        self.session: tuple[str, int] | None = None   # (key id, session) followed
        self._last_rx_ns = 0

    def age_ns(self, cmd: BrakeCommand, rx_mono_ns: int, rx_wall_ns: int) -> int:
        """Monotonic: transport age (same host only). Wall: age since the radar cycle."""
        if self.age_clock is AgeClock.MONOTONIC:
            return rx_mono_ns - cmd.header.pub_mono_ns
        return rx_wall_ns - cmd.header.stamp_ns

    def data_age_ns(self, cmd: BrakeCommand, rx_mono_ns: int, rx_wall_ns: int) -> int:
        """Age of the radar data: since the cycle's last CAN frame (monotonic, same host)
        or since the radar cycle's stamp (wall)."""
        if self.age_clock is AgeClock.MONOTONIC and cmd.radar_last_frame_mono_ns > 0:
            return rx_mono_ns - cmd.radar_last_frame_mono_ns
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
        problem = mac_problem(payload, cmd, self.keys)
        if problem is not None:
            return Rejection(problem)
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
        assert cmd.auth is not None   # mac_problem checked it
        session = (cmd.auth.key_id, cmd.auth.session)
        seq = cmd.header.seq
        last = self.last_seq
        restart = False
        gap = 0
        if last is None or session != self.session:
            if last is not None and stream_alive:
                return Rejection.OTHER_SESSION
            restart = last is not None
        else:
            if seq == last:
                return Rejection.DUPLICATE
            if seq < last:
                return Rejection.OLD_SEQUENCE
            gap = seq - last - 1
            allowed = JUMP_SLACK + (rx_mono_ns - self._last_rx_ns) * self.max_rate_per_ns
            if gap > allowed:
                return Rejection.SEQ_JUMP
        self.last_seq = seq
        self.session = session
        self._last_rx_ns = rx_mono_ns
        return Accepted(cmd, gap, restart, self.data_age_ns(cmd, rx_mono_ns, rx_wall_ns))
