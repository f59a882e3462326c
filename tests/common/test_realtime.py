"""Real-time scheduling for the latency path (common/realtime.py): a thread made SCHED_FIFO
once, the Zenoh I/O threads found by name, a refusal logged once and survived, the
collector frozen; the router's flag. Every policy changed here is put back."""

import contextlib
import gc
import logging
import os
import sys
import threading
from collections.abc import Iterator

import pytest

from aeb_radar_camera.common import realtime
from aeb_radar_camera.common.config.realtime import RealtimeSettings
from aeb_radar_camera.common.keys import BRAKE_STATUS
from aeb_radar_camera.common.realtime import ThreadRealtime, apply_process, zenoh_io_threads
from tests.support import ServiceProcess, free_port, open_bus, port_open, python_module, wait_for

LOG = logging.getLogger("test.realtime")


def policy(tid: int = 0) -> int:
    return os.sched_getscheduler(tid)


def normal(tid: int = 0) -> None:
    os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))


def in_thread(fn) -> object:
    """Run `fn` on a new thread (never the test runner's) and return its result."""
    out: list[object] = []
    t = threading.Thread(target=lambda: out.append(fn()))
    t.start()
    t.join(10)
    return out[0]


def test_ensure_makes_the_calling_thread_fifo_once_and_is_idempotent(monkeypatch):
    calls: list[int] = []
    real = realtime.set_fifo

    def counting(priority: int, tid: int = 0) -> None:
        calls.append(priority)
        real(priority, tid)

    monkeypatch.setattr(realtime, "set_fifo", counting)
    rt = ThreadRealtime(RealtimeSettings(priority=7), LOG, "test")

    def body() -> tuple[int, int]:
        rt.ensure()
        rt.ensure()
        got = (policy(), os.sched_getparam(0).sched_priority)
        normal()
        return got

    assert in_thread(body) == (os.SCHED_FIFO, 7)
    assert calls == [7]


def test_priority_zero_changes_nothing():
    rt = ThreadRealtime(RealtimeSettings(priority=0), LOG, "test")

    def body() -> int:
        rt.ensure()
        return policy()

    assert in_thread(body) == os.SCHED_OTHER


def test_fifo_for_holds_the_priority_for_the_block_only():
    def body() -> tuple[object, ...]:
        with realtime.fifo_for(31) as granted:
            inside = (granted, policy(), os.sched_getparam(0).sched_priority)
        with realtime.fifo_for(0) as granted_zero:
            zero = (granted_zero, policy())
        return inside, (policy(), os.sched_getparam(0).sched_priority), zero

    assert in_thread(body) == ((True, os.SCHED_FIFO, 31), (os.SCHED_OTHER, 0),
                               (False, os.SCHED_OTHER))


def test_fifo_for_refused_runs_the_block_unchanged(monkeypatch):
    def refuse(*args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(realtime, "set_fifo", refuse)

    def body() -> tuple[bool, int]:
        with realtime.fifo_for(31) as granted:
            return granted, policy()

    assert in_thread(body) == (False, os.SCHED_OTHER)


def test_a_refusal_is_logged_once_and_the_thread_keeps_running(monkeypatch, caplog):
    def refuse(*args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    rt = ThreadRealtime(RealtimeSettings(priority=10), LOG, "test")
    with caplog.at_level(logging.WARNING):
        in_thread(rt.ensure)
        in_thread(rt.ensure)
    assert rt.refused
    assert sum("realtime_refused" in r.message for r in caplog.records) == 1


@pytest.fixture
def restore() -> Iterator[None]:
    """Every thread of this process back to normal scheduling afterwards."""
    interval = sys.getswitchinterval()
    try:
        yield
    finally:
        sys.setswitchinterval(interval)
        gc.unfreeze()
        for tid in realtime.thread_names():
            with contextlib.suppress(OSError):
                normal(tid)


def test_apply_process_makes_zenoh_io_threads_fifo_and_freezes_the_collector(router, restore):
    with open_bus(router) as bus:
        bus.subscribe_raw(BRAKE_STATUS, lambda *a: None)
        found = wait_for(zenoh_io_threads, 30, what="Zenoh's rx/tx threads")
        done = apply_process(RealtimeSettings(priority=3), LOG)
        assert {f"{name}:3" for name in found.values()} <= set(done)
        assert all(policy(tid) == os.SCHED_FIFO for tid in found)
        assert all(os.sched_getparam(tid).sched_priority == 3 for tid in found)
        assert gc.get_freeze_count() > 0
        assert sys.getswitchinterval() <= realtime.GIL_SWITCH_INTERVAL_S


def test_other_threads_go_one_below_and_real_time_ones_keep_their_priority(restore):
    release = threading.Event()
    ready = threading.Barrier(3)
    tids: dict[str, int] = {}

    def worker(name: str, fifo: int) -> None:
        tids[name] = threading.get_native_id()
        if fifo:
            realtime.set_fifo(fifo)
        ready.wait()
        release.wait(10)

    threads = [threading.Thread(target=worker, args=("decoder", 0)),
               threading.Thread(target=worker, args=("timer", 21))]
    for t in threads:
        t.start()
    ready.wait()
    try:
        apply_process(RealtimeSettings(priority=20), LOG)
        assert os.sched_getparam(tids["decoder"]).sched_priority == 19
        assert policy(tids["decoder"]) == os.SCHED_FIFO
        assert os.sched_getparam(tids["timer"]).sched_priority == 21
    finally:
        release.set()
        for t in threads:
            t.join(10)


def test_router_flag_makes_every_router_thread_fifo(tmp_path):
    port = free_port()
    proc = ServiceProcess("router", python_module(
        "aeb_radar_camera.common.router", "--listen", f"tcp/127.0.0.1:{port}",
        "--realtime-priority", "4"),
        tmp_path)
    try:
        wait_for(lambda: port_open(port), 60, 0.05, "router port")
        tids = [int(t) for t in os.listdir(f"/proc/{proc.pid}/task")]
        assert tids and all(policy(t) == os.SCHED_FIFO for t in tids)
        assert "realtime_thread thread=router" in proc.output()
    finally:
        proc.stop()
