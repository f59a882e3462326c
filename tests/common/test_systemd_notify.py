"""sd_notify spoken directly (common/systemd.py): datagrams on $NOTIFY_SOCKET, a path or
an abstract name, and a watchdog that only pings when systemd asked this process to."""

import os
import socket
import threading

import pytest

from aeb_radar_camera.common import systemd
from tests.notify_support import NotifyListener


@pytest.fixture
def listener(tmp_path):
    with NotifyListener(tmp_path / "notify") as lst:
        yield lst


def test_ready_and_status_arrive_as_one_datagram_with_the_senders_pid(listener,
                                                                      monkeypatch):
    monkeypatch.setenv("NOTIFY_SOCKET", listener.address)
    assert systemd.ready("serving")
    pid, text = listener.receive(5.0)
    assert pid == os.getpid()
    assert text == "READY=1\nSTATUS=serving"


def test_an_abstract_socket_name_is_reached():
    name = f"aeb-test-{os.getpid()}-{threading.get_ident()}"
    with NotifyListener(f"@{name}") as lst:
        assert systemd.notify("STOPPING=1", env={"NOTIFY_SOCKET": f"@{name}"})
        assert lst.receive(5.0)[1] == "STOPPING=1"


@pytest.mark.parametrize("value", ["", "relative/path", "vsock:2:1234"])
def test_no_socket_or_an_unknown_transport_is_a_no_op(value, tmp_path):
    assert systemd.notify("READY=1", env={"NOTIFY_SOCKET": value}) is False


def test_a_vanished_socket_is_not_an_error(tmp_path):
    assert systemd.notify("READY=1", env={"NOTIFY_SOCKET": str(tmp_path / "gone")}) is False


@pytest.mark.parametrize(("env", "enabled"), [
    ({}, False),
    ({"WATCHDOG_USEC": "2000000"}, True),
    ({"WATCHDOG_USEC": "2000000", "WATCHDOG_PID": str(os.getpid())}, True),
    ({"WATCHDOG_USEC": "2000000", "WATCHDOG_PID": "1"}, False),     # another process's
    ({"WATCHDOG_USEC": "0"}, False),
    ({"WATCHDOG_USEC": "soon"}, False),
])
def test_the_watchdog_follows_systemds_variables(env, enabled):
    dog = systemd.Watchdog(env=env)
    assert dog.enabled is enabled
    assert dog.period_s == (1.0 if enabled else None)


def test_feed_pings_at_most_every_quarter_interval(listener):
    now = [100.0]
    dog = systemd.Watchdog(env={**listener.env, "WATCHDOG_USEC": "4000000"},
                           clock=lambda: now[0])
    for t in (100.0, 100.5, 100.99, 101.0, 101.2, 102.5):
        now[0] = t
        dog.feed()
    # sent at 100.0, 101.0 and 102.5
    assert dog.sent == 3
    assert [listener.receive(5.0)[1] for _ in range(3)] == ["WATCHDOG=1"] * 3


def test_wait_feeds_while_it_waits_and_returns_when_the_event_is_set(listener):
    dog = systemd.Watchdog(env={**listener.env, "WATCHDOG_USEC": "200000"})   # 0.2 s
    stop = threading.Event()
    assert dog.wait(stop, 0.5) is False
    assert dog.sent >= 3                     # every 0.05 s at most, 0.1 s at least
    threading.Timer(0.05, stop.set).start()
    assert dog.wait(stop, 60.0) is True


def test_a_disabled_watchdog_waits_like_the_event():
    stop = threading.Event()
    stop.set()
    assert systemd.Watchdog(env={}).wait(stop, 60.0) is True


def test_the_listener_sees_nothing_when_nothing_is_sent(listener):
    with pytest.raises(socket.timeout):
        listener.receive(0.05)
