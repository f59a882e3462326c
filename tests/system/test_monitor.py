"""`aeb monitor`: its pure aggregation and view, and the command against a live bus."""

import json
import subprocess
import threading

import pytest

from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.keys import BRAKE_STATUS, RADAR_TRACKS
from aeb_radar_camera.common.messages import BrakeState, Decision, Verification
from aeb_radar_camera.tools.monitor.state import MonitorState
from aeb_radar_camera.tools.monitor.view import render_text, snapshot
from tests.support import START_TIMEOUT_S, HealthWatch, open_bus, python_module
from tests.system.messages import (
    brake_status,
    radar_tracks,
    target,
    track,
    verified_targets,
)

MS = 1_000_000


def feed_tracks(state: MonitorState, n: int, period_ms: float, start_seq: int = 0,
                skip: tuple[int, ...] = ()) -> int:
    t = 0
    for i in range(n):
        seq = start_seq + i
        if seq in skip:
            continue
        t = int(i * period_ms * MS)
        msg = radar_tracks(seq, (track(1, 12.0), track(2, 30.0, 2.0, False)),
                           stamp_ns=10_000 * MS + t - 3 * MS, mono_ns=t - 1 * MS)
        state.observe(RADAR_TRACKS, "aeb/ego/radar/front/tracks", msg, t, 10_000 * MS + t)
    return t


def test_rates_latencies_and_sequence_gaps():
    state = MonitorState(same_host=True)
    now = feed_tracks(state, 41, 75.0, skip=(10, 11))
    [view] = state.key_views(now)
    assert view.count == 39
    assert view.rate_hz == pytest.approx(1000 / 75.0, rel=0.1)
    assert view.alive and view.on_rate
    assert view.age_p50_ms == pytest.approx(3.0)
    assert view.transport_p50_ms == pytest.approx(1.0)
    assert view.seq_gaps == 2
    # Far from the publishers, monotonic stamps mean nothing: no transport latency.
    remote = MonitorState(same_host=False)
    now = feed_tracks(remote, 5, 75.0)
    assert remote.key_views(now)[0].transport_p50_ms is None


def test_rate_falls_to_zero_when_a_key_goes_silent():
    state = MonitorState(same_host=True)
    now = feed_tracks(state, 20, 75.0)
    later = now + 10_000 * MS
    [view] = state.key_views(later)
    assert view.rate_hz == 0.0 and view.last_age_s == pytest.approx(10.0)
    assert not view.alive and not view.on_rate
    # Alive but at half the nominal rate: off rate.
    slow = MonitorState(same_host=True)
    now = feed_tracks(slow, 20, 150.0)
    [view] = slow.key_views(now)
    assert view.alive and not view.on_rate


def test_snapshot_and_text_show_health_brake_tracks_and_targets():
    state = MonitorState(same_host=True)
    now = feed_tracks(state, 5, 75.0)
    state.observe(BRAKE_STATUS, "aeb/ego/brake/status",
                  brake_status(3, BrakeState.BRAKING), now, now)
    from aeb_radar_camera.common.keys import FUSION_TARGETS

    state.observe(FUSION_TARGETS, "aeb/ego/fusion/primary/targets",
                  verified_targets("primary", 4, (target(1, 12.0, Decision.BRAKE,
                                                         Verification.VERIFIED),)), now, now)
    state.on_health("radar", "front", True, 0)
    state.on_health("fusion", "primary", True, 0)
    state.on_health("fusion", "primary", False, now)
    snap = snapshot(state, now + 2000 * MS, "ego", "tcp/127.0.0.1:7447")
    json.dumps(snap)      # plain data
    assert {(h["service"], h["alive"]) for h in snap["health"]} == {("radar", True),
                                                                   ("fusion", False)}
    assert snap["brake"]["state"] == "BRAKING"
    assert [t["id"] for t in snap["tracks"]["front"]["tracks"]] == [1, 2]
    text = render_text(snap)
    assert "fusion/primary DOWN 2s" in text
    assert "BRAKE    BRAKING" in text
    assert "TRACKS   front: 2 (1 confirmed)" in text
    assert "verified" in text and "edge_density" in text


@pytest.mark.slow
def test_monitor_command_sees_a_live_bus(router):
    stop = threading.Event()
    with open_bus(router, source="radar/front") as bus:
        tracks_pub = bus.publisher(RADAR_TRACKS, sensor="front")
        status_pub = bus.publisher(BRAKE_STATUS)
        token = bus.declare_health("radar", "front")

        def publish() -> None:
            seq = 0
            while not stop.wait(0.05):
                tracks_pub.put(radar_tracks(seq, (track(1, 12.0),), wall_ns(), mono_ns()))
                if seq % 2 == 0:
                    status_pub.put(brake_status(seq, BrakeState.ARMED, wall_ns(), mono_ns()))
                seq += 1

        thread = threading.Thread(target=publish, daemon=True)
        thread.start()
        try:
            HealthWatch(bus).wait_alive("radar", "front")
            proc = subprocess.run(
                python_module("aeb_radar_camera.tools.cli", "monitor", "--connect", router,
                              "--once", "--json",
                              "--duration", "4"),
                capture_output=True, text=True, timeout=START_TIMEOUT_S + 30)
            assert proc.returncode == 0, proc.stderr
            snap = json.loads(proc.stdout.strip().splitlines()[-1])
            assert any(h["service"] == "radar" and h["instance"] == "front" and h["alive"]
                       for h in snap["health"])
            keys = {k["key"]: k for k in snap["keys"]}
            tracks = keys["aeb/ego/radar/front/tracks"]
            assert 10.0 < tracks["rate_hz"] < 30.0
            assert tracks["transport_p50_ms"] is not None and tracks["transport_p50_ms"] < 100
            assert snap["brake"]["state"] == "ARMED"
            assert snap["tracks"]["front"]["tracks"][0]["range_m"] == 12.0
            # Plain text when stdout is not a terminal, one table per interval.
            proc = subprocess.run(
                python_module("aeb_radar_camera.tools.cli", "monitor", "--connect", router,
                              "--duration", "2.5",
                              "--interval", "1"),
                capture_output=True, text=True, timeout=START_TIMEOUT_S + 30)
            assert proc.returncode == 0, proc.stderr
            assert proc.stdout.count("AEB monitor") >= 2
            assert "\x1b[" not in proc.stdout
            assert "radar/front UP" in proc.stdout
        finally:
            stop.set()
            thread.join(5)
            token.undeclare()


def test_monitor_exits_2_on_a_bad_endpoint():
    proc = subprocess.run(python_module("aeb_radar_camera.tools.cli", "monitor", "--connect",
                                        "nonsense",
                                        "--once"), capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "error:" in proc.stderr
