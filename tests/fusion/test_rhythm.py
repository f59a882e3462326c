"""decode = before_radar: the radar's rhythm (pure), a simulated timeline showing that
radar cycles get the same frames while a third of the frames are never decoded, and the
decoder thread waiting for the due time."""

import logging
import random
from collections import deque

import numpy as np

from common.clock import mono_ns
from services.fusion.frames import DECODE_LEAD_S, DecodedFrame, FrameDecoder, select_frame
from services.fusion.rhythm import RadarRhythm
from tests.fusion.test_frames import compressed
from tests.support import wait_for

MS = 1_000_000
LEAD = round(DECODE_LEAD_S * 1e9)


def steady(period_ns: int = 74 * MS, n: int = 6, start: int = 1_000 * MS) -> RadarRhythm:
    rhythm = RadarRhythm()
    for i in range(n):
        rhythm.on_cycle(start + i * period_ns)
    return rhythm


def test_the_next_cycle_is_due_one_median_period_after_the_last():
    rhythm = steady()
    last = 1_000 * MS + 5 * 74 * MS
    assert rhythm.period_ns == 74 * MS
    assert rhythm.decode_at(last + 10 * MS, LEAD) == last + 74 * MS - LEAD
    # Within the lead before the next cycle, or past it (radar late): decode at once.
    assert rhythm.decode_at(last + 62 * MS, LEAD) is None
    assert rhythm.decode_at(last + 500 * MS, LEAD) is None


def test_no_rhythm_until_enough_steady_cycles():
    rhythm = RadarRhythm()
    for i in range(4):                      # 3 intervals: not yet
        rhythm.on_cycle(i * 74 * MS)
        assert rhythm.decode_at(i * 74 * MS + MS, LEAD) is None
    rhythm.on_cycle(4 * 74 * MS)
    assert rhythm.period_ns == 74 * MS
    # A gap (a lost cycle, a radar restart) makes it irregular: every frame again...
    rhythm.on_cycle(4 * 74 * MS + 400 * MS)
    assert rhythm.period_ns is None and rhythm.decode_at(4 * 74 * MS + 401 * MS, LEAD) is None
    # ... until the gap has left the history.
    t = 4 * 74 * MS + 400 * MS
    for _ in range(8):
        t += 74 * MS
        rhythm.on_cycle(t)
    assert rhythm.period_ns == 74 * MS
    # A repeated or older arrival is ignored.
    rhythm.on_cycle(t)
    rhythm.on_cycle(t - MS)
    assert rhythm.period_ns == 74 * MS


def simulate(before_radar: bool, align: bool, seconds: float = 20.0, seed: int = 3,
             frame_latency_ms: float = 8.0, radar_latency_ms: float = 4.0,
             decode_ms: float = 1.0) -> tuple[list[int | None], int, int]:
    """A camera at 30 fps and a radar at about 13.5 Hz, with jittered latencies, through
    the decoder's policy (as in FrameDecoder: one pending frame, decoded when
    RadarRhythm says so; a worker that wakes at the due time it last computed).
    Returns the capture index of the frame each radar cycle would use, the frames
    decoded and the frames received."""
    rng = random.Random(seed)
    events: list[tuple[int, int, int, int]] = []       # (time, kind, index, stamp)
    for k in range(int(seconds * 30)):
        capture = int(k * 1e9 / 30) + 5 * MS
        arrival = capture + int((frame_latency_ms + rng.uniform(-2, 2)) * MS)
        events.append((arrival, 0, k, capture))
    stamp = 20 * MS
    j = 0
    while stamp < seconds * 1e9:
        arrival = stamp + int((radar_latency_ms + rng.uniform(-1, 1)) * MS)
        events.append((arrival, 1, j, stamp))
        stamp += int(rng.uniform(72, 76) * MS)
        j += 1
    events.sort()
    rhythm = RadarRhythm()
    ring: deque[DecodedFrame] = deque(maxlen=4)
    done: list[tuple[int, DecodedFrame]] = []             # decodes finishing later
    pending: tuple[int, int, int] | None = None            # (index, capture, arrival)
    wake: int | None = None
    decoded = 0
    chosen: list[int | None] = []
    pixel = np.zeros((1, 1), np.uint8)

    def decode(item: tuple[int, int, int], at: int) -> None:
        nonlocal decoded
        decoded += 1
        k, capture, arrival = item
        done.append((at + int(decode_ms * MS), DecodedFrame("front", k, capture, arrival, pixel)))

    def wake_up(now: int) -> None:
        """The worker's step: decode the waiting frame if it is time, else sleep on."""
        nonlocal pending, wake
        at = rhythm.decode_at(now, LEAD)
        if at is None:
            assert pending is not None
            decode(pending, now)
            pending, wake = None, None
        else:
            wake = at

    for t, kind, index, stamp in events:
        while pending is not None and wake is not None and wake <= t:
            wake_up(wake)
        for fin, f in sorted(done, key=lambda d: d[0]):
            if fin <= t:
                ring.append(f)
        done = [d for d in done if d[0] > t]
        if kind == 0:
            item = (index, stamp, t)
            if not before_radar:
                decode(item, t)
                continue
            pending = item              # a newer frame overtakes the one waiting
            wake_up(t)
        else:
            rhythm.on_cycle(t)
            best = select_frame(tuple(ring), stamp, 100 * MS, align)
            chosen.append(None if best is None else best.seq)
    return chosen, decoded, sum(1 for e in events if e[1] == 0)


def test_before_radar_gives_the_radar_cycles_the_same_frames_and_skips_a_third():
    for align in (True, False):
        every, decoded_all, frames = simulate(before_radar=False, align=align)
        lazy, decoded_lazy, _ = simulate(before_radar=True, align=align)
        assert decoded_all == frames
        warm = 20                     # cycles before the rhythm is established
        pairs = list(zip(every[warm:], lazy[warm:], strict=True))
        same = sum(a == b for a, b in pairs)
        assert same >= 0.97 * len(pairs), (align, same, len(pairs))
        # Where they differ, the lazy policy used the frame just before: never none.
        assert all(b is not None and a is not None and a - b <= 1 for a, b in pairs)
        assert decoded_lazy <= 0.7 * frames, (decoded_lazy, frames)


def test_with_the_radar_silent_every_frame_is_decoded():
    _, decoded, frames = simulate(before_radar=True, align=True, seconds=0.2)
    assert decoded == frames                       # too few cycles for a rhythm


def test_the_decoder_keeps_only_the_newest_frame_while_waiting_for_the_radar():
    now = mono_ns()
    # The last cycle arrived just now, every 0.4 s: the next is due in 0.4 s.
    rhythm = steady(period_ns=400 * MS, start=now - 5 * 400 * MS)
    due = rhythm.decode_at(mono_ns(), LEAD)
    assert due is not None
    decoder = FrameDecoder(848, 480, logging.getLogger("test"), "front", rhythm)
    for seq in range(3):
        decoder.submit(compressed(seq=seq), "k", mono_ns())
    feed = decoder.snapshot()
    assert (feed.received, feed.skipped, feed.dropped, feed.frames) == (3, 2, 0, ())
    decoder.start()
    try:
        wait_for(lambda: decoder.snapshot().frames, 10, what="the newest frame decoded")
        assert mono_ns() >= due                     # not before the radar's due time
        assert [f.seq for f in decoder.snapshot().frames] == [2]
    finally:
        decoder.stop()
