"""The actuator line protocol: exact bytes, every reason a line is refused, and a reader
that survives any byte stream."""

import random

import pytest

from aeb_radar_camera.services.brake.protocol import (
    MAX_LINE,
    Ack,
    ActuatorState,
    BadLine,
    Command,
    Fault,
    HostMode,
    LineReader,
    Nak,
    ProtocolError,
    Query,
    Report,
    command_line,
    crc16,
    decode,
    encode,
    level_to_wire,
)

# The examples printed in docs/actuator-protocol.md: the page and the code must agree.
DOC_EXAMPLES = [
    (Command(42, 80, 250, HostMode.BRAKING), b"$C,1,42,80,250,B*CC79\n"),
    (Command(43, 0, 250, HostMode.FAILSAFE), b"$C,1,43,0,250,F*8D63\n"),
    (Ack(42, 37.5, ActuatorState.OK), b"$A,1,42,37.5,OK*A781\n"),
    (Ack(43, 80.0, ActuatorState.FAULT), b"$A,1,43,80.0,FAULT*0761\n"),
    (Fault(3, "motor overcurrent"), b"$F,1,3,motor overcurrent*8A20\n"),
    (Fault(1, "watchdog ttl expired"), b"$F,1,1,watchdog ttl expired*3E4A\n"),
    (Nak(None, BadLine.CRC), b"$N,1,,CRC*A02A\n"),
    (Nak(44, BadLine.RANGE), b"$N,1,44,RANGE*ECB0\n"),
    (Query(), b"$Q,1*C09B\n"),
    (Report(100, 98.7, ActuatorState.OK), b"$R,1,100,98.7,OK*031E\n"),
    (Report(0, 0.0, ActuatorState.OK), b"$R,1,0,0.0,OK*4840\n"),
]


def test_crc_is_ccitt_false():
    assert crc16(b"123456789") == 0x29B1


@pytest.mark.parametrize(("frame", "line"), DOC_EXAMPLES)
def test_documented_examples_encode_and_decode_exactly(frame, line):
    assert encode(frame) == line
    assert decode(line[:-1]) == frame
    assert decode(line[:-1] + b"\r") == frame


def test_fast_command_line_matches_encode():
    for seq, level, mode in [(0, 0, HostMode.STANDBY), (2**32 - 1, 100, HostMode.FAULT)]:
        assert command_line(seq, level, 250, mode) == encode(Command(seq, level, 250, mode))


def _with_crc(body: bytes) -> bytes:
    return b"$" + body + b"*%04X" % crc16(body)


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        (b"$C,1,42,80,250,B*CC78", BadLine.CRC),
        (b"$C,1,42,81,250,B*CC79", BadLine.CRC),                 # a digit changed
        (b"$C,1,42,80,250,B*cc79", BadLine.FORMAT),              # lower-case CRC
        (b"$C,1,42,80,250,B", BadLine.FORMAT),                   # no CRC
        (b"C,1,42,80,250,B*CC79", BadLine.FORMAT),               # no '$'
        (_with_crc(b"C,1,42,80,250,B\x00"), BadLine.FORMAT),     # control character
        (_with_crc(b"C,2,42,80,250,B"), BadLine.VERSION),
        (_with_crc(b"C,,42,80,250,B"), BadLine.VERSION),
        (_with_crc(b"X,1,42"), BadLine.TYPE),
        (_with_crc(b"C,1,42,80,250"), BadLine.FORMAT),           # a field missing
        (_with_crc(b"C,1,42,80,250,B,1"), BadLine.FORMAT),       # a field too many
        (_with_crc(b"C,1,42,101,250,B"), BadLine.RANGE),
        (_with_crc(b"C,1,42,80,10,B"), BadLine.RANGE),           # ttl below 20 ms
        (_with_crc(b"C,1,42,80,2001,B"), BadLine.RANGE),
        (_with_crc(b"C,1,4294967296,80,250,B"), BadLine.RANGE),
        (_with_crc(b"C,1,042,80,250,B"), BadLine.FORMAT),        # leading zero
        (_with_crc(b"C,1,-1,80,250,B"), BadLine.FORMAT),
        (_with_crc(b"C,1,42,80,250,Z"), BadLine.FORMAT),         # unknown mode
        (_with_crc(b"A,1,42,100.1,OK"), BadLine.RANGE),
        (_with_crc(b"A,1,42,37.55,OK"), BadLine.FORMAT),         # one decimal exactly
        (_with_crc(b"A,1,42,37,OK"), BadLine.FORMAT),
        (_with_crc(b"A,1,42,37.5,BUSY"), BadLine.FORMAT),
        (_with_crc(b"F,1,0,x"), BadLine.RANGE),
        (_with_crc(b"F,1,3,bad;text"), BadLine.FORMAT),
        (_with_crc(b"N,1,,crc"), BadLine.FORMAT),
        (b"$" + b"A" * MAX_LINE, BadLine.LENGTH),
    ],
)
def test_unusable_lines_say_why(line, reason):
    with pytest.raises(ProtocolError) as err:
        decode(line)
    assert err.value.reason is reason


def test_each_side_refuses_the_other_sides_frames():
    with pytest.raises(ProtocolError) as err:
        decode(encode(Command(1, 0, 250, HostMode.ARMED))[:-1], frozenset("AFN"))
    assert err.value.reason is BadLine.TYPE
    with pytest.raises(ProtocolError) as err:
        decode(encode(Ack(1, 0.0, ActuatorState.OK))[:-1], frozenset("C"))
    assert err.value.reason is BadLine.TYPE


def test_encode_refuses_out_of_range_fields():
    for frame in (Command(1, 101, 250, HostMode.ARMED), Command(1, 0, 5, HostMode.ARMED),
                  Ack(2**32, 0.0, ActuatorState.OK), Fault(1000, "x"), Fault(1, "a*b")):
        with pytest.raises(ValueError):
            encode(frame)


def test_level_rounds_up_so_a_request_never_vanishes():
    assert [level_to_wire(x) for x in (0.0, -3.0, float("nan"), 0.2, 37.0, 37.01, 100.0,
                                       250.0)] == [0, 0, 0, 1, 37, 38, 100, 100]


def _lines(items):
    return [i for i in items if isinstance(i, bytes)]


def test_reader_joins_chunks_and_reports_noise_partial_and_length():
    r = LineReader()
    ack = encode(Ack(7, 1.0, ActuatorState.OK))
    out = []
    for i in range(len(ack)):                 # one byte at a time
        out += r.feed(ack[i:i + 1])
    assert _lines(out) == [ack[:-1]]
    assert r.feed(b"hello\n") == [BadLine.NOISE]
    assert r.feed(b"$A,1,7,1." + ack) == [BadLine.PARTIAL, ack[:-1]]
    assert r.feed(b"xx" + ack) == [BadLine.NOISE, ack[:-1]]
    out = r.feed(b"$" + b"9" * (MAX_LINE + 10))
    out += r.feed(b"more of the same line\n" + ack)
    assert out == [BadLine.LENGTH, ack[:-1]]
    assert r.feed(b"\r\n\n") == []            # blank lines are nothing


def test_reader_memory_stays_bounded_on_endless_garbage_without_newlines():
    r = LineReader()
    rng = random.Random(1)
    for _ in range(2000):
        r.feed(bytes(b for b in rng.randbytes(512) if b != 0x0A))
        assert len(r._buf) <= MAX_LINE + 1


def test_random_garbage_never_decodes_and_never_hides_the_next_good_line():
    """20k random bursts, each followed by a real ack."""
    rng = random.Random(5)
    r = LineReader()
    good = 0
    for i in range(20_000):
        kind = rng.randrange(3)
        if kind == 0:
            junk = rng.randbytes(rng.randint(1, 60))
        elif kind == 1:                                   # a cut-short ack
            line = encode(Ack(i, 50.0, ActuatorState.OK))
            junk = line[:rng.randint(1, len(line) - 2)]
        else:                                             # one flipped bit
            flipped = bytearray(encode(Ack(i, 50.0, ActuatorState.OK)))
            flipped[rng.randrange(1, len(flipped) - 1)] ^= 1 << rng.randrange(8)
            junk = bytes(flipped)
        ack = encode(Ack(i, 12.5, ActuatorState.OK))
        for item in r.feed(junk + ack):
            if isinstance(item, BadLine):
                continue
            try:
                frame = decode(item, frozenset("AFN"))
            except ProtocolError:
                continue
            assert frame == Ack(i, 12.5, ActuatorState.OK), (junk, item)
            good += 1
    # the good line's '$' always starts a fresh line, whatever came before it
    assert good == 20_000
