import io
import logging
import sys

import pytest

from aeb_radar_camera.common.freshness import Freshness, FreshnessTracker
from aeb_radar_camera.common.keys import RADAR_TRACKS
from aeb_radar_camera.common.log import RateLimitedLog, kv, setup_logging

S = 1_000_000_000


def test_alive_until_max_age_then_stale():
    f = Freshness("radar", max_age_s=0.16, nominal_rate_hz=13.3)
    assert not f.alive(0)
    assert f.age_s(0) is None
    f.observe(10 * S)
    assert f.alive(10 * S + int(0.16 * S))
    assert not f.alive(10 * S + int(0.161 * S))


def test_on_rate_from_the_registry_rate():
    f = Freshness.from_spec(RADAR_TRACKS, window_s=2.0)
    t = 0
    for _ in range(27):  # 75 ms period for 2 s
        t += 75_000_000
        f.observe(t)
    assert f.health(t).on_rate
    slow = Freshness.from_spec(RADAR_TRACKS, window_s=2.0)
    t = 0
    for _ in range(10):  # 150 ms period: alive between samples but half the rate
        t += 150_000_000
        slow.observe(t)
    h = slow.health(t)
    assert h.alive and not h.on_rate
    assert h.rate_hz == pytest.approx(1 / 0.150)


def test_rate_falls_as_an_input_goes_silent():
    f = Freshness("x", max_age_s=1.0, window_s=2.0)
    for i in range(11):
        f.observe(i * 100_000_000)
    assert f.rate_hz(1_000_000_000) == pytest.approx(10.0)
    assert f.rate_hz(2_000_000_000) == pytest.approx(5.0)   # 10 intervals over 2 s
    assert f.rate_hz(3_100_000_000) == 0.0                  # all older than the window


def test_tracker_snapshot_names_each_input():
    tr = FreshnessTracker()
    tr.add(Freshness("a", 1.0))
    tr.add(Freshness("b", 1.0))
    tr.observe("a", 5)
    snap = tr.snapshot(10)
    assert snap["a"].alive and not snap["b"].alive
    assert not tr.all_alive(10)


def test_rate_limited_log_holds_back_repeats_and_counts_them(caplog):
    now = [0.0]
    rl = RateLimitedLog(logging.getLogger("t"), interval_s=5.0, clock=lambda: now[0])
    with caplog.at_level(logging.WARNING):
        assert rl.warning("k", "bad_frame", id="0x7FF")
        for _ in range(9):
            assert not rl.warning("k", "bad_frame", id="0x7FF")
        assert rl.warning("other", "x")
        now[0] = 5.0
        assert rl.warning("k", "bad_frame", id="0x7FF")
    lines = [r.getMessage() for r in caplog.records]
    assert lines == ["bad_frame id=0x7FF", "x", "bad_frame id=0x7FF repeated=9"]


def test_kv_quotes_values_with_spaces():
    assert kv("e", a=1, b="two words", c=0.5) == "e a=1 b='two words' c=0.5"


def test_log_handler_follows_the_current_stderr(monkeypatch):
    """A handler that kept the stderr of the day it was set up would write to a closed
    stream later (a test harness's capture) and print "Logging error" instead."""
    log = setup_logging("handler-test")
    for buf in (io.StringIO(), io.StringIO()):
        monkeypatch.setattr(sys, "stderr", buf)
        log.warning(kv("first_stream_closed_yet", n=1))
        assert "first_stream_closed_yet n=1" in buf.getvalue()
        buf.close()
