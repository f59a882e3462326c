"""Arrivals: the first matching item, from another thread, from a position on; positions
that stay valid while a bounded history drops its older half; a timeout that says what
was awaited."""

import re
import threading

import pytest

from aeb_radar_camera.tools.arrivals import Arrivals


def test_waits_for_an_item_added_by_another_thread_from_a_position_on():
    got: Arrivals[int] = Arrivals()
    assert got.first(lambda _: True, 0.0, start=5) is None

    def write() -> None:
        for i in range(100):
            got.add(i % 10)

    writer = threading.Thread(target=write)
    writer.start()
    try:
        assert got.wait(lambda _: True, 30.0, start=99) == (99, 9)   # not before the 100th
        assert got.wait(lambda v: v == 7, 30.0) == (7, 7)
        assert got.wait(lambda v: v == 7, 30.0, start=8) == (17, 7)
    finally:
        writer.join(30)
    assert len(got) == 100 and got.last() == 9 and got.since(97) == [7, 8, 9]


def test_a_bounded_history_keeps_positions():
    got: Arrivals[int] = Arrivals(keep=4)
    for i in range(10):
        got.add(i)
    assert len(got) == 10 and got.items == [6, 7, 8, 9]
    assert got.since(0) == [6, 7, 8, 9] and got.since(8) == [8, 9]
    assert got.first(lambda v: v == 3, 0.0) is None           # dropped
    assert got.first(lambda v: v >= 0, 0.0, start=7) == (7, 7)


def test_the_timeout_says_what_was_awaited():
    got: Arrivals[str] = Arrivals()
    got.add("status")
    assert got.first(lambda v: v == "brake", 0.01) is None
    with pytest.raises(TimeoutError, match=re.escape(
            "no brake command within 0.01 s among 1 received; last: 'status'")):
        got.wait(lambda v: v == "brake", 0.01, what="brake command")
