"""Validation of incoming BrakeCommands: instance, schema, MAC, fields, age, session and
sequence. Pure."""

import enum
import math
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass

from aeb_radar_camera.common.command_auth import CommandKey, mac_problem
from aeb_radar_camera.common.config.brake import AgeClock
from aeb_radar_camera.common.messages import BrakeCommand, Decision, DecodeError, decode

JUMP_SLACK = 16   # sequence numbers an authenticated command may skip beyond the rate bound
# Accepted commands remembered (sequence number -> MAC, level): a command at or behind the
# reference within this many is a byte-identical duplicate or a second sender
RECENT = 64


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
    # a second sender in the followed session: a command at or behind the reference that
    # is not the one accepted there (or was skipped), and every command of the session
    # until its sequence has been consistent again for the deadline
    SEQ_CONFLICT = "seq_conflict"


@dataclass(frozen=True, slots=True)
class Accepted:
    cmd: BrakeCommand
    gap: int          # commands missing since the previous accepted one (0 when contiguous)
    restart: bool     # a new baseline (a new session, or a resync): arming starts anew
    data_age_ns: int  # age of the radar data the command was built from
    resync: bool = False   # the same session taken up again at a new sequence number


class CommandValidator:
    """Decides whether one received payload is a usable command.

    `expected_key` is the concrete key of the configured instance: anything published on
    another key is WRONG_INSTANCE before any decoding. A command must carry a valid MAC
    of one of `keys` (the instance's, by key id), be fresh, and continue the session it
    belongs to: within a session the sequence must increase, by at most JUMP_SLACK plus
    `max_rate_hz` times the time since the last accepted command. Another session of the
    key (a restarted fusion) is taken up only while the current one is silent
    (`stream_alive` false); its first command resets the sequence baseline. So is a jump
    of the followed session beyond the bound once that stream is silent (a resync: a
    fusion that ran ahead while the brake could not follow, e.g. under a flood), so that
    the legitimate stream is never locked out for longer than the deadline.

    A command at or behind the reference that is not byte for byte the one accepted at
    its sequence number (or one that a jump skipped) means two senders hold the key in
    one session: SEQ_CONFLICT. From then on every command of the session is refused
    SEQ_CONFLICT, so that neither stream moves the brake (it reaches FAILSAFE on its
    deadline), until the session's received sequence numbers have followed one another
    without a break for `conflict_ns`; the next one is then a resync. `revert_level` is
    set on the refusal that starts a conflict: the level of the last command accepted
    before the contested sequence number (what the brake followed before the second
    sender moved it). Nothing else that is rejected changes any state.
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
        conflict_ns: int = 200_000_000,
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
        self.conflict_ns = conflict_ns
        self._recent: OrderedDict[int, tuple[bytes, float]] = OrderedDict()
        self._conflict_until: int | None = None   # in conflict: consistent until then
        self._conflict_prev = 0                    # in conflict: the last received seq
        self.revert_level: float | None = None     # set by the refusal opening a conflict
        self.unknown_key_id: str | None = None     # set by an UNKNOWN_KEY refusal

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
        self.revert_level = None
        problem = mac_problem(payload, cmd, self.keys)
        if problem is not None:
            if problem == "unknown_key" and cmd.auth is not None:
                self.unknown_key_id = cmd.auth.key_id
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
        restart = resync = False
        gap = 0
        if last is None or session != self.session:
            if last is not None and stream_alive:
                return Rejection.OTHER_SESSION
            restart = last is not None
            self._conflict_until = None
        elif self._conflict_until is not None:
            consistent = seq == self._conflict_prev + 1
            self._conflict_prev = seq
            if not consistent:
                self._conflict_until = rx_mono_ns + self.conflict_ns
                return Rejection.SEQ_CONFLICT
            if rx_mono_ns < self._conflict_until:
                return Rejection.SEQ_CONFLICT
            self._conflict_until = None        # one sender again: taken up afresh
            restart = resync = True
        elif seq <= last:
            seen = self._recent.get(seq)
            if seen is not None and seen[0] == cmd.auth.mac:
                return Rejection.DUPLICATE
            if seen is None and seq < last - RECENT:
                return Rejection.OLD_SEQUENCE
            return self._open_conflict(seq, rx_mono_ns)
        else:
            gap = seq - last - 1
            allowed = JUMP_SLACK + (rx_mono_ns - self._last_rx_ns) * self.max_rate_per_ns
            if gap > allowed:
                if stream_alive:
                    return Rejection.SEQ_JUMP
                restart = resync = True    # the stream ran ahead while it was not followed
                gap = 0
        if restart:
            self._recent.clear()
        self._recent[seq] = (cmd.auth.mac, level)
        if len(self._recent) > RECENT:
            self._recent.popitem(last=False)
        self.last_seq = seq
        self.session = session
        self._last_rx_ns = rx_mono_ns
        return Accepted(cmd, gap, restart, self.data_age_ns(cmd, rx_mono_ns, rx_wall_ns),
                        resync)

    def _open_conflict(self, seq: int, rx_mono_ns: int) -> Rejection:
        """A second sender in the followed session: the level before `seq` (the contested
        sequence number) is what the brake goes back to."""
        before = [lvl for s, (_, lvl) in self._recent.items() if s < seq]
        self.revert_level = before[-1] if before else 0.0
        self._conflict_until = rx_mono_ns + self.conflict_ns
        self._conflict_prev = seq
        return Rejection.SEQ_CONFLICT

    @property
    def in_conflict(self) -> bool:
        return self._conflict_until is not None
