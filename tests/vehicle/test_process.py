"""The vehicle gateway as its own process (`aeb vehicle`, the shipped replay config)
behind a Zenoh router on loopback, with subscribers in the test:

- the sample drive, with a silence cut into it, decoded through the DBC: every published
  value is one cantools decodes from the log (converted as the config says), in the
  log's order, the whole drive covered;
- stale state at process level: when the CAN input goes silent, when the log ends and
  when the gateway stops, a subscriber's `VehicleState` reports stale within its bound
  and counts it, and the gateway's status says the bus is silent (ended);
- `aeb echo` shows the messages.
"""

import itertools
import json
import signal
import subprocess
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cantools
import pytest

from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.keys import EGO_MOTION, VEHICLE_DRIVER, VEHICLE_STATUS
from aeb_radar_camera.common.messages.radar import BusState
from aeb_radar_camera.common.messages.vehicle import Gear
from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.common.vehicle_state import StateFreshness, VehicleState
from tests.support import REPO, HealthWatch, ServiceProcess, open_bus, python_module, wait_for
from tests.vehicle.drive import LOG
from tests.vehicle.helpers import SHIPPED, decoded

pytestmark = pytest.mark.slow

REPLAY = DEPLOY / "vehicle-replay.toml"
GAP_AT_S = 2.5          # log time (from its first frame) where the silence is cut in
GAP_S = 1.2             # longer than silent_after_s (0.5 s)
BOUND_S = EGO_MOTION.max_age_s or 0.0
SIGNAL_BOUND_S = SHIPPED.signal_max_age_s
# how late a check may see what it must see on a loaded 2-core machine
SLACK_S = 0.5


def log_with_a_gap(path: Path) -> Path:
    """The sample drive with GAP_S of silence at GAP_AT_S."""
    lines = LOG.read_text().splitlines(keepends=True)
    t0 = float(lines[0].split(")")[0][1:])
    out = []
    for line in lines:
        t = float(line.split(")")[0][1:])
        if t - t0 >= GAP_AT_S:
            line = f"({t + GAP_S:.6f}){line.split(')', 1)[1]}"
        out.append(line)
    path.write_text("".join(out))
    return path


@dataclass
class Watched:
    """What a subscriber saw: messages with their arrival times, the gateway's status, and
    its VehicleState checked every 5 ms (the moments it turned stale or fresh)."""

    state: VehicleState = field(default_factory=VehicleState)
    motion: list[tuple[Any, int, int]] = field(default_factory=list)   # msg, mono, wall
    driver: list[tuple[Any, int, int]] = field(default_factory=list)
    status: list[Any] = field(default_factory=list)
    turns: list[tuple[int, StateFreshness]] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)
    stop: threading.Event = field(default_factory=threading.Event)

    def subscribe(self, bus) -> None:
        bus.subscribe(EGO_MOTION, lambda m, k: self._on(m, self.motion, self.state.motion))
        bus.subscribe(VEHICLE_DRIVER, lambda m, k: self._on(m, self.driver, self.state.driver))
        bus.subscribe(VEHICLE_STATUS, lambda m, k: self._status(m), gateway="main")
        threading.Thread(target=self._check, daemon=True).start()

    def _on(self, msg, into, state_input) -> None:
        mono, wall = mono_ns(), wall_ns()
        with self.lock:
            into.append((msg, mono, wall))
            state_input.observe(msg, mono, wall)

    def _status(self, msg) -> None:
        with self.lock:
            self.status.append(msg)

    def _check(self) -> None:
        last = None
        while not self.stop.wait(0.005):
            now = mono_ns()
            with self.lock:
                freshness = self.state.motion.check(now).freshness
            if freshness is not last:
                self.turns.append((now, freshness))
                last = freshness

    def statuses(self) -> list[Any]:
        with self.lock:
            return list(self.status)

    def last_status(self):
        s = self.statuses()
        return s[-1] if s else None


def start_gateway(tmp_path: Path, router: str, *settings: str) -> ServiceProcess:
    sets = [a for s in settings for a in ("--set", s)]
    return ServiceProcess("vehicle", python_module(
        "aeb_radar_camera.tools.cli", "vehicle", "--config", str(REPLAY), "--connect", router,
        "--set", "gateway.status_period_s=0.5", *sets), tmp_path)


def decoded_series(log: Path) -> dict[str, list[Any]]:
    """Every mapped signal's values in log order, as cantools decodes them and the
    config converts them (written out here, not the gateway's code)."""
    from can.io.canutils import CanutilsLogReader

    motion, driver = SHIPPED.motion, SHIPPED.driver
    assert motion.speed and motion.yaw_rate and driver.gear and driver.kickdown
    assert driver.brake_pedal_pressed
    gears = {0: Gear.PARK, 1: Gear.REVERSE, 2: Gear.NEUTRAL, 3: Gear.DRIVE}
    out: dict[str, list[Any]] = {k: [] for k in (
        "speed", "yaw", "angle", "rate", "pedal", "kickdown", "pressed", "pressure", "gear")}
    for msg in CanutilsLogReader(str(log)):
        try:
            v = decoded(msg)
        except (KeyError, cantools.database.DecodeError):
            continue
        for key, name, convert in (
                ("speed", "VehicleSpeed", lambda x: motion.speed.scale * x),
                ("yaw", "YawRate", float), ("angle", "SteeringWheelAngle", float),
                ("rate", "SteeringWheelRate", float), ("pedal", "AcceleratorPedal", float),
                ("kickdown", "Kickdown", lambda x: x > driver.kickdown.above),
                ("pressed", "BrakePedalPressed", lambda x: x > driver.brake_pedal_pressed.above),
                ("pressure", "BrakePressure", float), ("gear", "GearLever", gears.get)):
            if name in v:
                out[key].append(convert(v[name]))
    return out


def in_log_order(published: list[Any], series: list[Any], what: str) -> int:
    """Each published value is one of the series, never one from before the previous
    one; returns the index of the last match. AssertionError naming the value else."""
    i = 0
    for n, value in enumerate(published):
        while i < len(series) and series[i] != value:
            i += 1
        assert i < len(series), f"{what}: published #{n} = {value!r} is not in the log " \
                                "after the previous one"
    return i


def test_the_sample_drive_is_decoded_as_cantools_decodes_it_and_silence_goes_stale(
        tmp_path, router):
    log = log_with_a_gap(tmp_path / "drive-with-a-gap.log")
    watched = Watched()
    with open_bus(router) as bus:
        health = HealthWatch(bus)
        watched.subscribe(bus)
        proc = start_gateway(tmp_path, router, f"gateway.replay.file={json.dumps(str(log))}",
                             "gateway.replay.loop=false")
        try:
            health.wait_alive("vehicle", "main")
            wait_for(lambda: (s := watched.last_status()) is not None
                     and s.bus_state is BusState.ENDED, 90, 0.05, "the replay's end")
            wait_for(lambda: watched.turns and watched.turns[-1][1] is StateFreshness.STALE,
                     30, what="stale after the end")
            proc.signal(signal.SIGTERM)
            assert proc.proc.wait(30) == 0, proc.output()
        finally:
            watched.stop.set()
            proc.stop()
        wait_for(lambda: not health.is_alive("vehicle", "main"), 30, what="token gone")

    with watched.lock:
        motion, driver, status = list(watched.motion), list(watched.driver), watched.status
    # -- decoded as cantools decodes the log, in its order, the whole drive covered
    series = decoded_series(log)
    # 50 Hz on an idle machine; a starved gateway skips ticks (never bursts): what matters
    # here is that every value is right and the drive covered end to end
    assert len(motion) >= 0.5 * 50 * 13.0, len(motion)
    speeds = [abs(m.speed_mps) for m, _, _ in motion]
    end = in_log_order(speeds, series["speed"], "speed")
    assert end >= len(series["speed"]) - 10          # up to the log's last frames
    assert max(speeds) == max(series["speed"])
    in_log_order([m.yaw_rate_dps for m, _, _ in motion], series["yaw"], "yaw rate")
    msgs = [d for d, _, _ in driver]
    for key, name in (("angle", "steering_wheel_angle_deg"), ("rate", "steering_wheel_rate_dps"),
                      ("pedal", "accelerator_pedal_pct"), ("kickdown", "kickdown"),
                      ("pressed", "brake_pedal_pressed"), ("pressure", "brake_pressure_bar"),
                      ("gear", "gear")):
        in_log_order([getattr(d, name) for d in msgs], series[key], name)
    assert [g for i, g in enumerate(d.gear for d in msgs) if i == 0 or g is not msgs[i - 1].gear]\
        == [Gear.PARK, Gear.DRIVE, Gear.NEUTRAL, Gear.REVERSE]
    assert any(d.kickdown for d in msgs) and max(d.steering_wheel_angle_deg for d in msgs) == 60
    gear_at = {d.header.pub_mono_ns: d.gear for d in msgs}
    for m, _, _ in motion:     # backwards is negative, from the gear of the same instant
        gear = gear_at.get(m.header.pub_mono_ns)
        if gear is not None and m.speed_mps != 0:
            assert (m.speed_mps < 0) == (gear is Gear.REVERSE)
    # never a value older than its bound: the newest within the signal bound of arrival
    ages = [(wall - m.header.stamp_ns) / 1e9 for m, _, wall in motion]
    assert max(ages) <= SIGNAL_BOUND_S + SLACK_S, max(ages)

    # -- the silence and the end, as the subscriber saw them (a loaded machine may add
    # short stale spells of its own: they are counted too, never hidden)
    arrivals = [mono for _, mono, _ in motion]
    longest, before = max(((b - a) / 1e9, i) for i, (a, b) in
                          enumerate(itertools.pairwise(arrivals)))
    assert longest > GAP_S - 2 * SIGNAL_BOUND_S - SLACK_S     # nothing published meanwhile
    stale_at = [t for t, f in watched.turns if f is StateFreshness.STALE]
    assert watched.state.motion.counts.get("went_stale") >= len(stale_at) >= 2
    for last_arrival in (arrivals[before], arrivals[-1]):
        seen = next(t for t in stale_at if t > last_arrival)
        assert BOUND_S <= (seen - last_arrival) / 1e9 <= BOUND_S + SLACK_S
    # -- and as the gateway said it
    states = [s.bus_state for s in status]
    ready_then_silent = next(i for i, s in enumerate(status)
                             if s.bus_state is BusState.SILENT and any(p.ready for p in
                                                                       status[:i]))
    silent = status[ready_then_silent]
    assert not silent.ready and silent.not_ready_reason == "no CAN frames received recently"
    assert any(s.ready for s in status[ready_then_silent:])          # back after the gap
    assert states[-1] is BusState.ENDED and status[-1].not_ready_reason == "replay ended"
    assert status[-1].rejected == {"decode_error": 1, "unmapped_gear:7": 1}
    assert "vehicle_stopped code=0" in proc.log_path.read_text()


def test_a_gateway_that_stops_goes_stale_at_its_subscribers_and_aeb_echo_shows_it(
        tmp_path, router):
    watched = Watched()
    with open_bus(router) as bus:
        health = HealthWatch(bus)
        watched.subscribe(bus)
        proc = start_gateway(tmp_path, router)      # the shipped replay: looping
        try:
            health.wait_alive("vehicle", "main")
            wait_for(lambda: len(watched.motion) >= 20 and len(watched.driver) >= 20, 60,
                     what="motion and driver")
            echo = {key: subprocess.run(
                python_module("aeb_radar_camera.tools.cli", "echo", key, "--count", "2",
                              "--timeout", "30",
                              "--connect", router),
                capture_output=True, text=True, timeout=120, cwd=REPO)
                for key in ("vehicle/motion", "vehicle/driver", "vehicle_status")}
            proc.signal(signal.SIGTERM)
            assert proc.proc.wait(30) == 0, proc.output()
            wait_for(lambda: watched.turns[-1][1] is StateFreshness.STALE, 30,
                     what="stale once the gateway stopped")
        finally:
            watched.stop.set()
            proc.stop()
        wait_for(lambda: not health.is_alive("vehicle", "main"), 30, what="token gone")

    for key, done in echo.items():
        assert done.returncode == 0, (key, done.stderr)
        lines = [json.loads(line) for line in done.stdout.splitlines()]
        assert len(lines) == 2, done.stdout
        assert {line["type"] for line in lines} == {
            "vehicle/motion": {"EgoMotion"}, "vehicle/driver": {"DriverInputs"},
            "vehicle_status": {"VehicleStatus"}}[key]
    motion = json.loads(echo["vehicle/motion"].stdout.splitlines()[0])
    assert set(motion["msg"]) == {"header", "speed_mps", "yaw_rate_dps"}
    status = json.loads(echo["vehicle_status"].stdout.splitlines()[0])
    assert status["key"] == "aeb/ego/vehicle/gateway/main/status"
    assert status["msg"]["interface"] == "replay" and status["msg"]["dbc"] == "generic-car.dbc"

    stale_at = [t for t, f in watched.turns if f is StateFreshness.STALE]
    assert watched.state.motion.counts.get("went_stale") >= len(stale_at) >= 1
    last_arrival = watched.motion[-1][1]
    assert BOUND_S <= (stale_at[-1] - last_arrival) / 1e9 <= BOUND_S + SLACK_S
    check = watched.state.motion.check(mono_ns())
    assert check.freshness is StateFreshness.STALE and "vehicle/motion: newest is" in check.reason
