"""`aeb faults` quick mode (one injection of each fault into one running stack), as CI
runs it: every fault but the stuck subscriber is injected, each gets its required
response within its bound, the stack recovers after each, and the table is written as
Markdown, JSON and PNG. About a minute on a 2-core machine."""

import io
import json

import pytest

from aeb_radar_camera.tools.faults import harness, report
from aeb_radar_camera.tools.faults.registry import all_faults

pytestmark = pytest.mark.slow


# Left out here: on the full simulated stack (no real-time priorities) a host loaded
# by other jobs delays fusion's commands past the brake's deadline while the fault's
# load fills the stuck process's link (docs/reliability.md); tests/security/
# test_stuck_subscriber.py covers the defect with the brake as deployed.
NOT_IN_QUICK = ["stuck subscriber"]


def test_quick_mode_every_fault_answered_within_bound(tmp_path):
    log = io.StringIO()
    records, info = harness.run(tmp_path, 1, "quick", log, skip=NOT_IN_QUICK)
    md, js, png = report.write(tmp_path, records, info)
    context = f"\n{md.read_text()}\n{log.getvalue()[-3000:]}"
    assert not info.stopped_early, context
    assert [r.fault for r in records] == [f.name for f in all_faults()
                                          if f.name not in NOT_IN_QUICK]
    for rec in records:
        # the link cut runs everywhere: over a veth pair, or over the loopback relay
        assert not rec.skipped, context
        assert len(rec.outcomes) == 1, context
        assert rec.unrecovered == 0, context
    assert not info.unexpected_exits, context
    # One injection of each is a sample: in the soak (docs/reliability.md) about 1 in 200
    # injections misses its bound on a loaded 2-core machine (a thread woken late, the
    # harness's own simulator falling behind). A fault that misses here gets one more
    # injection into a fresh stack; it must pass that one, and both are reported.
    missed = [r for r in records if not r.outcomes[0].ok]
    if missed:
        again, info2 = harness.run(tmp_path / "again", 1, "quick", log,
                                   only=[r.fault for r in missed])
        context = f"{context}\nagain:\n{log.getvalue()[-3000:]}"
        # (`only` matches parts of names: "frozen camera" runs "noisy frozen camera" too)
        by_name = {r.fault: r for r in again}
        assert {r.fault for r in missed} <= set(by_name), context
        for first in missed:
            second = by_name[first.fault]
            assert second.outcomes and second.outcomes[0].ok, (
                f"{first.fault}: {first.outcomes[0].detail}, again: "
                f"{second.outcomes[0].detail if second.outcomes else 'not injected'}{context}")
        assert not info2.unexpected_exits, context
    data = json.loads(js.read_text())
    assert len(data["faults"]) == len(records) and png is not None and png.is_file()


def test_link_cut_over_the_loopback_relay_fails_safe(tmp_path):
    """The fallback where network namespaces cannot be made (not root, no netns)."""
    records, info = harness.run(tmp_path, 1, "relay", io.StringIO(), only=["link cut"],
                                link_kind="relay")
    assert info.link.startswith("loopback relay")
    (rec,) = records
    assert len(rec.outcomes) == 1 and rec.outcomes[0].ok, rec.outcomes[0].detail
    assert "loopback relay" in rec.outcomes[0].detail


def _can_use_fifo(priority: int) -> bool:
    import os
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, OSError):
        return False
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    return True


@pytest.mark.skipif(not _can_use_fifo(20), reason="SCHED_FIFO not allowed here (not root, "
                    "no RLIMIT_RTPRIO); the quick test above runs the same faults without")
def test_faults_run_the_stack_at_the_deployed_realtime_priority(tmp_path):
    """`aeb faults --realtime-priority 20`: the stack's latency path runs SCHED_FIFO as
    deployed, the table says so, and a fault still gets its response."""
    records, info = harness.run(tmp_path, 1, "quick", io.StringIO(), only=["SIGKILL fusion"],
                                realtime_priority=20)
    log = (tmp_path / "stack.log").read_text()
    # the harness's stand-ins for hardware just below: a fault's load does not starve them
    assert info.scheduling.startswith("SCHED_FIFO 20; simulated hardware (")
    assert "sim-loop" in info.scheduling and info.scheduling.endswith("at SCHED_FIFO 10")
    for service in ("router", "brake", "fusion", "radar"):
        assert any(line.startswith(service) and "realtime_thread" in line
                   and "priority=" in line for line in log.splitlines()), (service, log[-3000:])
    (rec,) = records
    assert len(rec.outcomes) == 1 and rec.outcomes[0].response_ms is not None, rec.outcomes
    md, _, _ = report.write(tmp_path, records, info)
    assert f"scheduling: {info.scheduling}" in md.read_text()
