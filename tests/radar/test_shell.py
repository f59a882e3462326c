"""The radar service's I/O shell in-process (no Zenoh): replay, bad input, bus loss and
reopen, several radars on one bus, the 0x200 write confirmed from 0x201 over a real slcan
pty, ego motion forwarding."""

import threading
import time

import can
import msgspec
import pytest

from aeb_radar_camera.common.clock import wall_ns
from aeb_radar_camera.common.config.radar import (
    CanSettings,
    CycleSettings,
    EgoMotionSettings,
    Expect,
    Pace,
    RadarSettings,
    RadarWriteSettings,
    ReplaySettings,
    SensorSettings,
)
from aeb_radar_camera.common.messages.header import Header
from aeb_radar_camera.common.messages.radar import BusState
from aeb_radar_camera.common.messages.vehicle import EgoMotion
from aeb_radar_camera.services.radar.ars408 import (
    ObjectGeneral,
    RadarFrame,
    RadarStateFrame,
    SpeedInformation,
    decode_frame,
    encode,
    object_cycle_frames,
)
from aeb_radar_camera.services.radar.ports import radar_message
from aeb_radar_camera.services.radar.shell import RadarShell
from aeb_radar_camera.tools.sim.can_links import SlcanPtyLink
from tests.can_support import RECORDING, RECORDING_CYCLES
from tests.support import Collector, wait_for

FAST_REOPEN = CanSettings(interface="slcan", channel="unused", reopen_backoff_initial_s=0.01,
                          reopen_backoff_max_s=0.05, silent_after_s=0.3)
NO_EXTRAS = CycleSettings(expect_quality=Expect.NO, expect_extended=Expect.NO)


class Output:
    """A RadarOutput that keeps everything: `got_tracks` / `got_status` hold (msg, sensor)."""

    def __init__(self) -> None:
        self.got_tracks = Collector()
        self.got_status = Collector()
        self.served = threading.Event()

    def tracks(self, sensor, msg) -> None:
        self.got_tracks(msg, sensor)

    def status(self, sensor, msg) -> None:
        self.got_status(msg, sensor)

    def serving(self) -> None:
        self.served.set()

    def last_status(self, sensor: str = "front"):
        return next((m for m, k in reversed(self.got_status.items) if k == sensor), None)

    def status_where(self, predicate, timeout_s: float = 30, sensor: str = "front"):
        """The latest status of `sensor` once it satisfies `predicate`."""
        def found():
            st = self.last_status(sensor)
            return st if st is not None and predicate(st) else None

        return wait_for(found, timeout_s, what="a matching RadarStatus")


def cycle_messages(k: int, sensor_id: int = 0, x: float = 12.0) -> list[can.Message]:
    frames = object_cycle_frames([ObjectGeneral(1, x, 0.4, -2.0, 0.0, 0, 10.0)], k,
                                 sensor_id=sensor_id)
    return [msg(f, t=100.0 + 0.075 * k) for f in frames]


def msg(f: RadarFrame, t: float = 0.0) -> can.Message:
    return radar_message(f, t)


class ScriptedPort:
    """A bus whose recv() plays a list; an Exception entry is raised; then it idles."""

    def __init__(self, script: list) -> None:
        self.script = list(script)
        self.sent: list[can.Message] = []

    def recv(self, timeout=None):
        if not self.script:
            time.sleep(min(timeout or 0.01, 0.01))
            return None
        item = self.script.pop(0)
        if isinstance(item, Exception):
            raise item
        return item

    def send(self, m, timeout=None):
        self.sent.append(m)

    def shutdown(self):
        pass


def test_replay_as_fast_as_possible_publishes_every_cycle_then_ends():
    s = RadarSettings(can=CanSettings(interface="replay"),
                      replay=ReplaySettings(file=str(RECORDING), pace=Pace.FAST,
                                            exit_at_end=True))
    out = Output()
    assert RadarShell(s, out).run(threading.Event()) == 0
    tracks = out.got_tracks.messages
    assert len(tracks) == RECORDING_CYCLES and all(m.complete for m in tracks)
    assert [m.header.seq for m in tracks] == list(range(RECORDING_CYCLES))
    # Re-stamped to the wall clock: fusion aligns them with camera frames.
    assert abs(tracks[-1].header.stamp_ns - wall_ns()) < 60e9
    assert all(m.last_frame_mono_ns > 0 and m.processing_ns > 0 for m in tracks)
    final = out.last_status()
    assert final.bus_state is BusState.ENDED and not final.ready
    assert final.not_ready_reason == "replay ended"
    assert final.firmware == "4.30.2" and final.cycles_total == RECORDING_CYCLES
    assert final.rejected == {} and final.interface == "replay"
    assert out.served.is_set()


def test_bad_input_is_counted_and_never_stops_the_service(running):
    bad = [
        can.Message(is_error_frame=True, timestamp=1.0),
        can.Message(arbitration_id=0x60B, data=bytes(8), is_extended_id=True),
        can.Message(arbitration_id=0x60B, is_remote_frame=True, is_extended_id=False),
        msg(RadarFrame(0x123, b"\x01")),
        msg(RadarFrame(0x61A, b"\x01\x00\x00\x10")),              # sensor 1: not configured
        msg(RadarFrame(0x300, b"\x40\x00")),                       # another host's speed frame
    ]
    broken_cycle = [msg(RadarFrame(0x60A, b"\x02\x00\x05\x10"), t=100.1),
                    msg(RadarFrame(0x60B, b"\x01\x02\x03"), t=100.1),   # wrong DLC
                    msg(encode(ObjectGeneral(2, 12.0, 0.0, 0.0, 0.0, 0, 5.0)), t=100.1)]
    script = cycle_messages(0) + bad + broken_cycle + cycle_messages(2) + cycle_messages(3)
    out = Output()
    s = RadarSettings(can=FAST_REOPEN, cycle=NO_EXTRAS)
    running(RadarShell(s, out, lambda: ScriptedPort(script)))
    out.got_tracks.wait_count(4, 10)
    assert [m.complete for m in out.got_tracks.messages] == [True, False, True, True]
    assert out.got_tracks.messages[1].n_detections == 1
    status = out.status_where(lambda st: st.header.seq > 1, 10)
    assert {k: v for k, v in status.rejected.items()} == {
        "bus:error_frame": 1, "bus:extended_id": 1, "bus:remote_frame": 1,
        "bus:unknown_id": 1, "bus:unconfigured_sensor_id": 1, "bus:host_frame": 1,
        "wrong_dlc:Obj_1_General": 1,
    }
    assert status.cycles_incomplete == 1


def test_lost_bus_is_reopened_with_backoff(running):
    ports = iter([
        OSError("adapter unplugged"),
        ScriptedPort([*cycle_messages(0), can.CanOperationError("read failed")]),
        OSError("still gone"),
        ScriptedPort(cycle_messages(1) + cycle_messages(2)),
    ])

    def factory():
        p = next(ports)
        if isinstance(p, Exception):
            raise p
        return p

    out = Output()
    s = RadarSettings(can=FAST_REOPEN, cycle=NO_EXTRAS)
    running(RadarShell(s, out, factory))
    out.got_tracks.wait_count(3, 10)
    wait_for(lambda: out.last_status().bus_reopens == 2, 10, what="two reopens")
    states = [m.bus_state for m in out.got_status.messages]
    assert BusState.REOPENING in states and BusState.ACTIVE in states
    reopening = next(m for m in out.got_status.messages if m.bus_state is BusState.REOPENING)
    assert not reopening.ready and "reopening" in reopening.not_ready_reason
    assert out.last_status().rejected.get("bus:bus_failure") == 1


def test_two_radars_on_one_bus_publish_under_their_own_names(running):
    script = []
    for k in range(3):
        script += cycle_messages(k, sensor_id=0, x=10.0) + cycle_messages(k, sensor_id=1, x=20.0)
    s = RadarSettings(can=FAST_REOPEN, cycle=NO_EXTRAS,
                      sensors=(SensorSettings("front", 0), SensorSettings("left", 1)))
    out = Output()
    running(RadarShell(s, out, lambda: ScriptedPort(script)))
    out.got_tracks.wait_count(6, 10)
    by_sensor: dict[str, list] = {}
    for m, key in out.got_tracks.items:
        by_sensor.setdefault(key, []).append(m)
    assert sorted(by_sensor) == ["front", "left"]
    assert by_sensor["front"][-1].tracks[0].x_m == pytest.approx(10.0, abs=0.2)
    assert by_sensor["left"][-1].tracks[0].x_m == pytest.approx(20.0, abs=0.2)
    assert by_sensor["left"][-1].header.source == "radar/left"
    assert wait_for(lambda: out.last_status("left"), 10).sensor_id == 1


def state_frame(output_type: int, temperature_error: int = 0) -> RadarFrame:
    return encode(RadarStateFrame(1, 200, 0, 0, temperature_error, 0, 0, 0, 1, 0, 1, 1,
                                  output_type, 0))


class PtyRadar:
    """A simulated radar behind an slcan pty: sends a cycle every 20 ms and answers a 0x200
    with a 0x201 of the given output type."""

    def __init__(self, answer_output_type: int | None, temperature_error: int = 0) -> None:
        self.answer = answer_output_type
        self.temperature_error = temperature_error
        self.link = SlcanPtyLink(on_frame=self.on_frame)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._cycles, daemon=True)

    def on_frame(self, f: RadarFrame) -> None:
        if f.arb_id == 0x200 and self.answer is not None:
            self.link.send([state_frame(self.answer, self.temperature_error)])

    def _cycles(self) -> None:
        k = 0
        while not self._stop.wait(0.02):
            if self.link.opened:
                self.link.send(object_cycle_frames(
                    [ObjectGeneral(3, 15.0, 0.0, 0.0, 0.0, 1, 5.0)], k))
                k += 1

    def __enter__(self) -> "PtyRadar":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(5)
        self.link.close()

    def settings(self, **configure) -> RadarSettings:
        return RadarSettings(
            can=CanSettings(interface="slcan", channel=self.link.path,
                            options={"sleep_after_open": 0}),
            cycle=NO_EXTRAS,
            sensors=(SensorSettings(configure=RadarWriteSettings(enabled=True, **configure)),),
        )


def test_configuration_written_and_confirmed_from_0x201_over_slcan(running):
    with PtyRadar(answer_output_type=1) as radar:
        out = Output()
        running(RadarShell(radar.settings(), out))
        cfg = radar.link.wait_frame(lambda f: f.arb_id == 0x200, 30)
        record = decode_frame(*cfg)[2]
        assert record.output_type_valid and record.output_type == 1
        assert record.max_distance_m == 200 and record.send_quality and record.send_ext_info
        assert not record.sensor_id_valid            # never moves the radar to other IDs
        out.status_where(lambda st: st.ready)
        assert not out.got_status.messages[0].ready
        assert radar.link.commands[:2] == ["C", "S6"]


def test_configuration_the_radar_does_not_take_is_reported_not_ready(running):
    with PtyRadar(answer_output_type=2) as radar:
        out = Output()
        running(RadarShell(radar.settings(confirm_timeout_s=0.2, attempts=2), out))
        status = out.status_where(lambda st: "differs" in st.not_ready_reason)
        assert not status.ready
        assert "output_type=clusters (want objects)" in status.not_ready_reason
        writes = [f for f in radar.link.received() if f.arb_id == 0x200]
        assert len(writes) == 2                      # the configured attempts, no more


def test_radar_error_bits_make_it_not_ready(running):
    with PtyRadar(answer_output_type=1, temperature_error=1) as radar:
        out = Output()
        running(RadarShell(radar.settings(), out))
        out.status_where(lambda st: st.not_ready_reason == "radar reports temperature error")
        assert out.last_status().radar_state.temperature_error


def test_ego_motion_is_forwarded_as_0x300_and_0x301(running):
    with PtyRadar(answer_output_type=None) as radar:
        s = RadarSettings(can=CanSettings(interface="slcan", channel=radar.link.path,
                                          options={"sleep_after_open": 0}),
                          ego_motion=EgoMotionSettings(forward=True, min_interval_s=0.0))
        out = Output()
        service = RadarShell(s, out)
        running(service)
        radar.link.wait_open(30)
        wait_for(lambda: out.served.is_set(), 30)

        def motion(speed: float, stamp_ns: int) -> EgoMotion:
            return EgoMotion(header=Header(seq=0, source="sim", stamp_ns=stamp_ns,
                                           pub_mono_ns=0), speed_mps=speed, yaw_rate_dps=-4.5)

        def forwarded() -> bool:
            service.on_ego_motion(motion(8.3, wall_ns()))
            return any(f.arb_id == 0x300 for f in radar.link.received())

        wait_for(forwarded, 30, 0.05)
        speed = radar.link.wait_frame(lambda f: f.arb_id == 0x300, 5)
        yaw = radar.link.wait_frame(lambda f: f.arb_id == 0x301, 5)
        assert decode_frame(*speed)[2] == pytest.approx(SpeedInformation(1, 8.3))
        assert decode_frame(*yaw)[2].yaw_rate_dps == pytest.approx(-4.5)
        service.on_ego_motion(motion(8.3, wall_ns() - 10**9))      # a second old: stale
        status = out.status_where(lambda st: st.rejected.get("ego_motion:stale") == 1)
        assert status.ego_motion_frames_sent >= 2


def test_disabled_ego_motion_sends_nothing():
    out = Output()
    port = ScriptedPort([])
    service = RadarShell(RadarSettings(can=FAST_REOPEN), out, lambda: port)
    service.on_ego_motion(EgoMotion(header=Header(seq=0, source="sim", stamp_ns=wall_ns(),
                                                  pub_mono_ns=0), speed_mps=3.0,
                                    yaw_rate_dps=0.0))
    assert port.sent == [] and service.ego_sent == {0: 0}


def test_unplugged_slcan_adapter_is_reported_and_retried(running):
    radar = PtyRadar(answer_output_type=1)
    with radar:
        s = msgspec.structs.replace(
            radar.settings(), can=CanSettings(
                interface="slcan", channel=radar.link.path, options={"sleep_after_open": 0},
                reopen_backoff_initial_s=0.01, reopen_backoff_max_s=0.05))
        out = Output()
        running(RadarShell(s, out))
        out.got_tracks.wait_count(3, 30)
    # The link is closed: the service's reads fail and the device is gone.
    status = out.status_where(lambda st: st.bus_state is BusState.REOPENING)
    assert not status.ready and status.rejected.get("bus:bus_failure") == 1


def test_stats_are_logged_periodically_and_at_the_end(running, caplog):
    # a stats line per period while serving, with the rate since the previous line
    caplog.set_level("INFO", logger="radar")
    script = [m for k in range(40) for m in cycle_messages(k)]
    s = RadarSettings(can=FAST_REOPEN, cycle=NO_EXTRAS, stats_period_s=0.05)
    out = Output()
    running(RadarShell(s, out, lambda: ScriptedPort(script)))

    def lines() -> list[str]:
        return [r.getMessage() for r in caplog.records if r.getMessage().startswith(
            "radar_stats ")]

    wait_for(lambda: len(lines()) >= 2 and "cycles=40 " in lines()[-1], 30,
             what="two radar_stats lines, the last after every cycle")
    fields = dict(kv.split("=", 1) for kv in lines()[-1].split()[1:])
    assert fields["sensor"] == "front" and fields["incomplete"] == "0"
    assert (fields["tracks"], fields["confirmed"]) == ("1", "1")
    assert float(fields["processing_us_max"]) >= float(fields["processing_us_p50"])
    assert fields["bus_state"] in ("active", "silent")
    assert any(float(dict(kv.split("=", 1) for kv in ln.split()[1:])["rate_hz"]) > 0
               for ln in lines())


def test_a_replay_logs_its_totals_when_it_ends(caplog):
    caplog.set_level("INFO", logger="radar")
    s = RadarSettings(can=CanSettings(interface="replay"),
                      replay=ReplaySettings(file=str(RECORDING), pace=Pace.FAST,
                                            exit_at_end=True))
    assert RadarShell(s, Output()).run(threading.Event()) == 0
    final = [r.getMessage() for r in caplog.records if r.getMessage().startswith("radar_stats")]
    assert final and f"cycles={RECORDING_CYCLES} " in final[-1]
    assert "incomplete=0 " in final[-1] and "rejected=0 " in final[-1]
