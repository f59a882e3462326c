"""The host <-> actuator line protocol, version 1 (specified in docs/actuator-protocol.md).

Pure: bytes in, frames or `BadLine` reasons out. Both sides use it: the brake service
(host) and the simulated actuator (which plays the firmware's side).

    $<TYPE>,<VERSION>,<fields...>*<CRC>\\n

CRC is CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over the bytes between '$' and '*',
written as four upper-case hex digits.
"""

import binascii
import enum
import math
import re
from dataclasses import dataclass

VERSION = 1
MAX_LINE = 80              # bytes from '$' to the end of the CRC, terminator excluded
SEQ_MODULO = 2**32
TTL_MIN_MS = 20
TTL_MAX_MS = 2000
FAULT_TEXT_MAX = 40

_HEX = frozenset(b"0123456789ABCDEF")
# What a line's body may hold: printable ASCII but the frame's own '$' and '*'
_BODY_BYTES = bytes(b for b in range(0x20, 0x7F) if b not in b"$*")
_UINT = re.compile(r"^(0|[1-9][0-9]{0,9})$")
_POSITION = re.compile(r"^(0|[1-9][0-9]{0,2})\.[0-9]$")
_FAULT_TEXT = re.compile(r"^[A-Za-z0-9 _.\-]{0,40}$")


class HostMode(enum.Enum):
    """The host's state as told to the actuator in every command (one letter)."""

    STANDBY = "S"
    ARMED = "A"
    BRAKING = "B"
    FAILSAFE = "F"   # the actuator shows the driver warning
    FAULT = "E"      # the host sees the actuator as faulty: driver warning too


class ActuatorState(enum.Enum):
    OK = "OK"          # following commands
    FAULT = "FAULT"    # cannot follow commands (see the last fault line)


class BadLine(enum.Enum):
    """Why a received line (or run of bytes) was discarded."""

    NOISE = "noise"        # bytes outside any line (no '$')
    PARTIAL = "partial"    # a line cut short by the next '$'
    LENGTH = "length"      # longer than MAX_LINE
    FORMAT = "format"      # no '*CRC' trailer, bad characters, wrong field count or syntax
    CRC = "crc"            # checksum mismatch
    TYPE = "type"          # unknown type, or a type this side never receives
    VERSION = "version"    # another protocol version
    RANGE = "range"        # a number outside its range


class ProtocolError(ValueError):
    """A line that is not a valid frame; `reason` says why."""

    def __init__(self, reason: BadLine, detail: str = "") -> None:
        super().__init__(f"{reason.value}: {detail}" if detail else reason.value)
        self.reason = reason


@dataclass(frozen=True, slots=True)
class Command:
    """Host to actuator: `$C,1,<seq>,<level>,<ttl_ms>,<mode>`."""

    seq: int
    level_pct: int
    ttl_ms: int
    mode: HostMode


@dataclass(frozen=True, slots=True)
class Ack:
    """Actuator to host: `$A,1,<seq>,<position>,<state>`."""

    seq: int
    position_pct: float
    state: ActuatorState


@dataclass(frozen=True, slots=True)
class Fault:
    """Actuator to host: `$F,1,<code>,<text>`."""

    code: int
    text: str


@dataclass(frozen=True, slots=True)
class Nak:
    """Actuator to host: `$N,1,<seq or empty>,<reason>`: a host line it could not use."""

    seq: int | None
    reason: BadLine


@dataclass(frozen=True, slots=True)
class Query:
    """Host to actuator: `$Q,1`: what do you hold? Sent by a host that starts, before it
    commands anything, so that a restarted host never releases a brake mid-stop."""


@dataclass(frozen=True, slots=True)
class Report:
    """Actuator to host: `$R,1,<target>,<position>,<state>`: the answer to a query: the
    level it holds as its target (0..100), its measured position, its state. Changes
    nothing on the actuator (not the target, not the watchdog)."""

    target_pct: int
    position_pct: float
    state: ActuatorState


# What one line of the protocol carries, parsed (either direction).
SerialFrame = Command | Ack | Fault | Nak | Query | Report

# Fault codes of version 1 (docs/actuator-protocol.md); 100..999 are vendor-specific.
FAULT_WATCHDOG = 1
FAULT_POSITION_SENSOR = 2
FAULT_MOTOR = 3
FAULT_SUPPLY = 4


def crc16(body: bytes) -> int:
    """CRC-16/CCITT-FALSE; check value crc16(b"123456789") == 0x29B1."""
    return binascii.crc_hqx(body, 0xFFFF)


def _frame(body: str) -> bytes:
    raw = body.encode("ascii")
    return b"$" + raw + b"*%04X\n" % crc16(raw)


def command_line(seq: int, level_pct: int, ttl_ms: int, mode: HostMode) -> bytes:
    """`encode(Command(...))` without the range checks: the host's hot path, for values it
    built itself (seq modulo SEQ_MODULO, level from level_to_wire, ttl from validated
    config)."""
    body = b"C,%d,%d,%d,%d,%s" % (VERSION, seq, level_pct, ttl_ms, mode.value.encode())
    return b"$%s*%04X\n" % (body, crc16(body))


def level_to_wire(level_pct: float) -> int:
    """A requested level as the protocol's integer percent: rounded up, so that a small
    non-zero request never becomes 0, and clamped to 0..100."""
    if not math.isfinite(level_pct) or level_pct <= 0.0:
        return 0
    return min(100, math.ceil(level_pct - 1e-9))


def encode(frame: SerialFrame) -> bytes:
    """The line for a frame, terminator included. Raises ValueError on an out-of-range
    field (a programming error: never put on the line)."""
    if isinstance(frame, Command):
        if not (0 <= frame.seq < SEQ_MODULO and 0 <= frame.level_pct <= 100
                and TTL_MIN_MS <= frame.ttl_ms <= TTL_MAX_MS):
            raise ValueError(f"command out of range: {frame}")
        return command_line(frame.seq, frame.level_pct, frame.ttl_ms, frame.mode)
    if isinstance(frame, Ack):
        if not (0 <= frame.seq < SEQ_MODULO and 0.0 <= frame.position_pct <= 100.0):
            raise ValueError(f"ack out of range: {frame}")
        return _frame(f"A,{VERSION},{frame.seq},{frame.position_pct:.1f},{frame.state.value}")
    if isinstance(frame, Fault):
        if not (1 <= frame.code <= 999 and _FAULT_TEXT.match(frame.text)):
            raise ValueError(f"fault out of range: {frame}")
        return _frame(f"F,{VERSION},{frame.code},{frame.text}")
    if isinstance(frame, Query):
        return _frame(f"Q,{VERSION}")
    if isinstance(frame, Report):
        if not (0 <= frame.target_pct <= 100 and 0.0 <= frame.position_pct <= 100.0):
            raise ValueError(f"report out of range: {frame}")
        return _frame(f"R,{VERSION},{frame.target_pct},{frame.position_pct:.1f},"
                      f"{frame.state.value}")
    seq = "" if frame.seq is None else str(frame.seq)
    return _frame(f"N,{VERSION},{seq},{frame.reason.value.upper()}")


def _uint(text: str, lo: int, hi: int) -> int:
    if not _UINT.match(text):
        raise ProtocolError(BadLine.FORMAT, f"not a decimal integer: {text!r}")
    value = int(text)
    if not lo <= value <= hi:
        raise ProtocolError(BadLine.RANGE, f"{value} outside {lo}..{hi}")
    return value


def _position(text: str) -> float:
    if not _POSITION.match(text):
        raise ProtocolError(BadLine.FORMAT, f"position {text!r}")
    pos = float(text)
    if pos > 100.0:
        raise ProtocolError(BadLine.RANGE, f"position {pos}")
    return pos


def _state(text: str) -> ActuatorState:
    try:
        return ActuatorState(text)
    except ValueError:
        raise ProtocolError(BadLine.FORMAT, f"state {text!r}") from None


def _fields(fields: list[str], n: int) -> list[str]:
    if len(fields) != n:
        raise ProtocolError(BadLine.FORMAT, f"{len(fields)} fields, expected {n}")
    return fields


def decode(line: bytes, accept: frozenset[str] = frozenset("CAFNQR")) -> SerialFrame:
    """Parse one line (from '$' to the CRC; a trailing '\\r' is ignored).

    `accept` lists the frame types this side receives (the host: "AFNR", the actuator:
    "CQ"). Raises ProtocolError with the reason the line is unusable.
    """
    if line.endswith(b"\r"):
        line = line[:-1]
    if len(line) > MAX_LINE:
        raise ProtocolError(BadLine.LENGTH, f"{len(line)} bytes")
    if len(line) < 7 or line[0] != 0x24 or line[-5] != 0x2A:   # '$' ... '*XXXX'
        raise ProtocolError(BadLine.FORMAT, "no $...*CRC frame")
    crc_text = line[-4:]
    body = line[1:-5]
    # translate deletes the allowed bytes: anything left is a bad one (checked in C, where
    # a generator over the bytes was the largest cost of an acknowledgement)
    if not _HEX.issuperset(crc_text) or body.translate(None, _BODY_BYTES):
        raise ProtocolError(BadLine.FORMAT, "bad characters")
    if crc16(body) != int(crc_text, 16):
        raise ProtocolError(BadLine.CRC)
    fields = body.decode("ascii").split(",")
    kind = fields[0]
    if kind not in accept:
        raise ProtocolError(BadLine.TYPE, repr(kind))
    if len(fields) < 2 or fields[1] != str(VERSION):
        raise ProtocolError(BadLine.VERSION, fields[1] if len(fields) > 1 else "missing")
    if kind == "C":
        _, _, seq, level, ttl, mode = _fields(fields, 6)
        try:
            host_mode = HostMode(mode)
        except ValueError:
            raise ProtocolError(BadLine.FORMAT, f"mode {mode!r}") from None
        return Command(_uint(seq, 0, SEQ_MODULO - 1), _uint(level, 0, 100),
                       _uint(ttl, TTL_MIN_MS, TTL_MAX_MS), host_mode)
    if kind == "A":
        _, _, seq, position, state = _fields(fields, 5)
        pos, act_state = _position(position), _state(state)
        return Ack(_uint(seq, 0, SEQ_MODULO - 1), pos, act_state)
    if kind == "Q":
        _fields(fields, 2)
        return Query()
    if kind == "R":
        _, _, target, position, state = _fields(fields, 5)
        target_pct = _uint(target, 0, 100)
        return Report(target_pct, _position(position), _state(state))
    if kind == "F":
        _, _, code, text = _fields(fields, 4)
        if not _FAULT_TEXT.match(text):
            raise ProtocolError(BadLine.FORMAT, "fault text")
        return Fault(_uint(code, 1, 999), text)
    _, _, seq, reason = _fields(fields, 4)
    try:
        nak_reason = BadLine(reason.lower())
    except ValueError:
        raise ProtocolError(BadLine.FORMAT, f"nak reason {reason!r}") from None
    if reason != reason.upper():
        raise ProtocolError(BadLine.FORMAT, f"nak reason {reason!r}")
    return Nak(None if seq == "" else _uint(seq, 0, SEQ_MODULO - 1), nak_reason)


class LineReader:
    """Splits a byte stream into candidate lines (each from '$' up to, not including, the
    newline), reporting what it had to throw away.

    A '$' always starts a new line: whatever came before it on the same line was cut
    short (PARTIAL) or was noise. A line that grows beyond MAX_LINE is reported once
    (LENGTH) and skipped up to the next '$' or newline. Memory stays bounded whatever
    arrives.
    """

    def __init__(self, max_line: int = MAX_LINE) -> None:
        self._max = max_line
        self._buf = bytearray()
        self._skipping = False   # inside a line already reported as too long or noise

    def feed(self, data: bytes) -> list[bytes | BadLine]:
        out: list[bytes | BadLine] = []
        buf = self._buf
        buf += data
        while (nl := buf.find(b"\n")) >= 0:
            segment = bytes(buf[:nl])
            del buf[:nl + 1]
            self._complete(segment, out)
        self._tail(out)
        return out

    def _leading(self, head: bytes, out: list[bytes | BadLine]) -> None:
        """Bytes before a '$': the rest of a skipped line, noise, or cut-short lines."""
        parts = head.split(b"$")
        if parts[0].strip(b"\r") and not self._skipping:
            out.append(BadLine.NOISE)
        out.extend(BadLine.PARTIAL for _ in parts[1:])
        self._skipping = False

    def _complete(self, segment: bytes, out: list[bytes | BadLine]) -> None:
        start = segment.rfind(b"$")
        if start < 0:
            if segment.strip(b"\r") and not self._skipping:
                out.append(BadLine.NOISE)
            self._skipping = False
            return
        self._leading(segment[:start], out)
        line = segment[start:]
        if len(line.rstrip(b"\r")) > self._max:
            out.append(BadLine.LENGTH)
        else:
            out.append(line)

    def _tail(self, out: list[bytes | BadLine]) -> None:
        buf = self._buf
        start = buf.rfind(b"$")
        if start < 0:
            if len(buf) > self._max:
                if not self._skipping:
                    out.append(BadLine.NOISE)
                    self._skipping = True
                buf.clear()
            return
        if start > 0:
            self._leading(bytes(buf[:start]), out)
            del buf[:start]
        if len(buf) > self._max + 1:   # + 1: a '\r' may still precede the newline
            out.append(BadLine.LENGTH)
            buf.clear()
            self._skipping = True
