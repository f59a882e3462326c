"""`aeb replay`: the stack runs unchanged on a recording.

- fusion + brake + the simulated actuator on the recorded radar tracks and camera
  frames of tests/data/recording/: fusion's decisions on the replay, cycle by cycle, are
  the recorded ones, and the actuator brakes;
- the radar service on the recorded raw CAN frames (an slcan pty): its tracks are the
  recorded ones;
- the replay's controls: rate, as fast as the subscribers, start and end, loop, another
  vehicle id, a remap.
"""

import re
import subprocess
import threading
from pathlib import Path

import pytest

from aeb_radar_camera.common.keys import BRAKE_STATUS, FUSION_BRAKE_CMD, RADAR_TRACKS
from aeb_radar_camera.common.messages import BrakeCommand, BrakeState, RadarTracks, decode
from aeb_radar_camera.common.net import free_port
from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.tools.recording.reader import Recording
from aeb_radar_camera.tools.sim.actuator import SimActuator
from aeb_radar_camera.tools.sim.stack import write_configs
from tests.support import (
    REPO,
    START_TIMEOUT_S,
    Collector,
    HealthWatch,
    ServiceProcess,
    open_bus,
    python_module,
    wait_for,
)

pytestmark = pytest.mark.slow

SIM = REPO / "tests" / "data" / "recording" / "pedestrian_standing_20kph.mcap"


def recorded(topic: str, msg_type):
    return [decode(r.data, msg_type) for r in Recording.open(SIM).records([topic])]


def replay(router: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(python_module("aeb_radar_camera.tools.cli", "replay", str(SIM),
                                        "--connect", router,
                                        "--quiet", *args),
                          capture_output=True, text=True, timeout=timeout, cwd=REPO)


def test_fusion_and_brake_on_a_replay_decide_as_recorded(router, tmp_path):
    actuator, _pair = SimActuator.on_pty(tmp_path / "actuator")
    actuator.start()
    # Fusion as it was when the recording was made (the combined check and the paper's
    # rule), under the recorded instance's name and key.
    configs = write_configs(tmp_path / "configs", router, str(tmp_path / "actuator"),
                            "/dev/null", fusion_config=DEPLOY / "fusion-combined.toml")
    as_recorded = {"fusion": ("--instance", "primary", "--set",
                              f"fusion.command_key={DEPLOY / 'keys' / 'primary.key'}"),
                   "brake": ()}
    procs = [ServiceProcess(name, python_module(f"aeb_radar_camera.services.{name}", "--config",
                                                str(configs.of(name)), "--connect", router,
                                                *as_recorded[name]),
                            tmp_path) for name in ("fusion", "brake")]
    try:
        with open_bus(router, source="test") as bus:
            health = HealthWatch(bus)
            health.wait_alive("fusion", "primary")
            health.wait_alive("brake", "main")
            commands, statuses = Collector(), Collector()
            bus.subscribe(FUSION_BRAKE_CMD, commands, instance="primary")
            bus.subscribe(BRAKE_STATUS, statuses)
            t0 = actuator.commands_since(0)[-1].t_ns if actuator.commands_since(0) else 0
            done = replay(router, "--keys", "radar_tracks,camera_jpeg,camera_info")
            assert done.returncode == 0, done.stderr
            want = recorded("aeb/ego/fusion/primary/brake_cmd", BrakeCommand)
            by_seq = {c.radar_seq: c for c in want}
            got = commands.wait_until(lambda c: c.radar_seq == want[-1].radar_seq, 30)
            del got
    finally:
        for p in procs:
            p.stop()
        actuator.stop()
    live = {c.radar_seq: c for c in commands.messages}
    # On a loaded host two replayed cycles can be waiting when fusion's radar thread runs:
    # it decides the newer and sheds the older, counted (services/fusion/shell.py), and
    # publishes no command for it. Every other recorded cycle gets one.
    shed = [int(n) for n in re.findall(r"tracks_shed=(\d+)", procs[0].output())]
    missing = sorted(set(by_seq) - set(live))
    assert len(missing) <= (shed[-1] if shed else 0), \
        f"recorded radar cycles {missing} got no command on the replay, {shed[-1:]} shed"
    assert len(missing) <= len(by_seq) // 10, missing
    mismatched = [(s, by_seq[s].decision.value, live[s].decision.value, live[s].reason)
                  for s in sorted(set(by_seq) & set(live))
                  if by_seq[s].decision != live[s].decision]
    assert not mismatched, mismatched
    assert any(c.decision.value == "BRAKE" for c in live.values())
    assert any(s.state is BrakeState.BRAKING for s in statuses.messages)
    assert any(r.cmd.level_pct == 100 for r in actuator.commands_since(t0))


def test_the_radar_runs_on_the_recorded_raw_can(router, tmp_path):
    path_file = tmp_path / "pty"
    rp = ServiceProcess("replay", python_module(
        "aeb_radar_camera.tools.cli", "replay", str(SIM), "--connect", router, "--keys",
        "radar_can",
        "--remap", "can/radar=can/replayed", "--can-pty", "--can-pty-path-file",
        str(path_file), "--quiet"), tmp_path)
    try:
        wait_for(lambda: path_file.exists() and path_file.read_text(), START_TIMEOUT_S, 0.05,
                 "the replay's pty")
        cfg = tmp_path / "radar.toml"
        cfg.write_text(f'vehicle = "ego"\n[zenoh]\nconnect = ["{router}"]\n[radar.can]\n'
                       f'interface = "slcan"\nchannel = "{path_file.read_text()}"\n'
                       'bitrate = 500000\noptions = { sleep_after_open = 0 }\n')
        with open_bus(router, source="test") as bus:
            tracks = Collector()
            bus.subscribe(RADAR_TRACKS, tracks, sensor="front")
            radar = ServiceProcess("radar", python_module("aeb_radar_camera.services.radar",
                                                          "--config",
                                                          str(cfg)), tmp_path)
            try:
                assert rp.proc.wait(120) == 0, rp.output()
                want = recorded("aeb/ego/radar/front/tracks", RadarTracks)
                tracks.wait_until(lambda t: t.meas_counter == want[-1].meas_counter, 30)
            finally:
                radar.stop()
    finally:
        rp.stop()
    live = {t.meas_counter: t for t in tracks.messages}
    assert set(t.meas_counter for t in want) <= set(live)
    for w in want:
        got = live[w.meas_counter]
        assert got.n_detections == w.n_detections
        assert [(t.track_id, t.confirmed) for t in got.tracks] == \
            [(t.track_id, t.confirmed) for t in w.tracks]
        for a, b in zip(got.tracks, w.tracks, strict=True):
            # The tracker's time step comes from the replay's receive times: close.
            assert abs(a.x_m - b.x_m) < 0.3 and abs(a.y_m - b.y_m) < 0.3


def test_rate_fast_window_loop_and_another_vehicle(router, tmp_path):
    first, last = Recording.open(SIM).time_range()
    span_s = (last - first) / 1e9
    with open_bus(router, vehicle="replay1", source="test") as bus:
        got = Collector()
        bus.subscribe(RADAR_TRACKS, got, sensor="front")
        done = replay(router, "--keys", "radar_tracks", "--vehicle", "replay1", "--rate", "4")
        assert done.returncode == 0, done.stderr
        assert len(got.wait_count(83, 30)) == 83
        assert "4x" in done.stderr and "83" in done.stderr
        windowed = Collector()
        bus.subscribe(RADAR_TRACKS, windowed, sensor="front")
        done = replay(router, "--keys", "radar_tracks", "--vehicle", "replay1", "--fast",
                      "--start", "2", "--end", "4")
        assert done.returncode == 0, done.stderr
        n = len(windowed.wait_count(20, 30))
        assert 20 <= n <= 30                  # 2 s of 13.5 Hz cycles
        looped = Collector()
        bus.subscribe(RADAR_TRACKS, looped, sensor="front")
        stop = threading.Event()
        proc = ServiceProcess("loop", python_module(
            "aeb_radar_camera.tools.cli", "replay", str(SIM), "--connect", router, "--keys",
            "radar_tracks",
            "--vehicle", "replay1", "--fast", "--start", "2", "--end", "3", "--loop", "--quiet"),
            tmp_path)
        try:
            msgs = looped.wait_count(40, 60)
        finally:
            proc.stop()
            stop.set()
        seqs = [m.header.seq for m in msgs[:40]]
        assert seqs == sorted(seqs) and len(set(seqs)) == 40   # numbered on across passes
    assert span_s > 5
    assert Path(SIM).stat().st_size < 5_000_000     # a kept fixture stays small


def test_a_replay_that_is_the_router_does_not_say_it_waits_for_one(tmp_path):
    listen = f"tcp/127.0.0.1:{free_port()}"
    done = subprocess.run(python_module(
        "aeb_radar_camera.tools.cli", "replay", str(SIM), "--listen", listen, "--keys",
        "radar_tracks",
        "--fast", "--quiet", "--log-level", "INFO"), capture_output=True, text=True,
        timeout=120, cwd=REPO)
    assert done.returncode == 0, done.stderr
    assert "published 83 messages" in done.stderr
    assert "waiting_for_router" not in done.stderr and "router_reached" not in done.stderr
