"""A stuck subscriber on the vehicle network (a monitor paused with Ctrl-Z, a recorder
whose disk hangs: tools/faults/stuck.py, **simulated**) subscribed to every key of the
vehicle, with the brake service, a fusion-like publisher and the router as their own
processes on loopback (tests/brake/rig.py), and camera-sized samples on the camera key
that fill the stuck process's link within seconds.

Once nothing more gets into the stuck process, the router can deliver nothing more to it.
A key published with congestion control BLOCK then holds the router's reader of the
publisher's link for up to Zenoh's `wait_before_close` (5 s): fusion's commands stop
reaching the brake and it goes FAILSAFE. With DROP the stuck process loses its own
samples and nobody else notices.

The bound is set for a loaded 2-core host, well under the stall it guards against: the
widest gap between the commands reaching the brake under `GAP_BOUND_MS` (the 5 s stall
of a BLOCK key fails it), and the brake ARMED on the real commands afterwards. On a
quiet host the gap is about one command period (docs/security.md).
"""

import itertools
import signal
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from aeb_radar_camera.common.messages import BrakeState, BrakeStatus
from aeb_radar_camera.tools.faults.stuck import wait_filled
from tests.brake.rig import BrakeRig, brake_rig
from tests.support import (
    ServiceProcess,
    host_exclusive,
    python_module,
    router_pid,
    wait_for,
)

pytestmark = pytest.mark.slow

PERIOD_MS = 50.0
# longer than Zenoh's wait_before_close (5 s), the longest a BLOCK sample waits
OBSERVE_S = 7.0
# well under that 5 s stall; a loaded host's scheduling delays stay far below it
GAP_BOUND_MS = 1500.0
# four of the load's samples
FILLED_MIN_BYTES = 1_000_000


@pytest.fixture
def rig(tmp_path: Path) -> Iterator[BrakeRig]:
    with brake_rig(tmp_path, watch_commands=False, realtime={"priority": 20}) as r:
        yield r


@pytest.mark.parametrize("how", ["sigstop", "blocking-callback"])
def test_a_stuck_subscriber_does_not_delay_the_brakes_commands(rig: BrakeRig, how: str):
    fusion = rig.publisher(level=0.0, period_ms=PERIOD_MS, name="fusion")
    stuck = ServiceProcess("stuck", python_module(
        "aeb_radar_camera.tools.faults.stuck", "--connect", rig.endpoint,
        *(["--block"] if how == "blocking-callback" else [])), rig.log_dir)
    load: ServiceProcess | None = None
    try:
        rig.wait_live(0, timeout_s=60)
        wait_for(lambda: "ready" in stuck.output() or not stuck.alive(), 60, 0.05,
                 "the stuck subscriber subscribed")
        assert stuck.alive(), stuck.output()
        _, before = rig.wait_status(lambda s: True, len(rig.status))
        with host_exclusive("flood"):
            mark = len(rig.status)
            t_freeze = time.monotonic_ns()
            if how == "sigstop":
                stuck.signal(signal.SIGSTOP)
            # from a process of its own: this one runs the simulated actuator
            load = loading = ServiceProcess("load", python_module(
                "aeb_radar_camera.tools.faults.stuck", "--connect", rig.endpoint, "--load"),
                rig.log_dir)
            wait_for(lambda: "ready" in loading.output() or not loading.alive(), 60, 0.05,
                     "the load publishing")
            assert loading.alive(), loading.output()
            # the fault in place: the stuck process's receive queue and the router's send
            # queue to it full
            filled, _ = wait_filled(stuck.pid, 60.0, router=router_pid(rig.endpoint))
            t_full = time.monotonic_ns()
            _, later = rig.wait_status(
                lambda s: s.header.pub_mono_ns > t_full + int(OBSERVE_S * 1e9), mark, 60,
                f"a status {OBSERVE_S} s after the stuck process's queue was full")
        statuses: list[BrakeStatus] = rig.status.since(mark)
        # the fault undone: the brake ARMED on the real commands (at once, unless the
        # loaded host delayed them beyond the deadline meanwhile: FAILSAFE, then ARMED)
        loading.stop()
        stuck.signal(signal.SIGCONT)
        stuck.stop()
        t_end = time.monotonic_ns()
        rig.wait_status(
            lambda s: s.state is BrakeState.ARMED and s.last_cmd_rx_mono_ns > t_end,
            len(rig.status), 30, "ARMED on the real commands after the fault")
    finally:
        if load is not None:
            load.stop()
        if stuck.alive():
            stuck.signal(signal.SIGCONT)
        stuck.stop()
        fusion.stop()
    # the load's samples in it, not only the stack's own traffic
    assert filled > FILLED_MIN_BYTES, filled
    window = [s for s in statuses if t_freeze <= s.header.pub_mono_ns <= later.header.pub_mono_ns]
    # the brake's receipts of the real commands, from the freeze on
    receipts = sorted({s.last_cmd_rx_mono_ns for s in window} | {t_freeze})
    widest_ms = max(b - a for a, b in itertools.pairwise(receipts)) / 1e6
    failsafe = sum(1 for a, b in itertools.pairwise(window)
                   if b.state is BrakeState.FAILSAFE and a.state is not BrakeState.FAILSAFE)
    misses = later.counters.get("deadline_misses", 0) - before.counters.get("deadline_misses", 0)
    print(f"\nstuck subscriber ({how}): {filled / 1e6:.1f} MB unread, widest gap between "
          f"the brake's commands {widest_ms:.1f} ms, FAILSAFE entered {failsafe} times, "
          f"{misses} deadline misses")
    assert widest_ms < GAP_BOUND_MS, widest_ms
    assert later.counters["commands"] - before.counters["commands"] > \
        0.5 * OBSERVE_S * 1000 / PERIOD_MS
