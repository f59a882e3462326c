"""The gateway's I/O shell in-process (no Zenoh): the sample drive replayed as fast as
possible, a bus that goes silent and comes back over a real slcan pty, frames the bus
itself spoils, and a fault in the core that must not stop the gateway."""

import threading

import can
import msgspec
import pytest

from aeb_radar_camera.common.config.can import CanSettings, Pace, ReplaySettings
from aeb_radar_camera.common.messages.radar import BusState
from aeb_radar_camera.services.radar.ars408.codec import RadarFrame
from aeb_radar_camera.services.vehicle.core import VehicleCore
from aeb_radar_camera.services.vehicle.shell import VehicleShell
from aeb_radar_camera.tools.sim.can_links import SlcanPtyLink
from tests.support import Collector, wait_for
from tests.vehicle.drive import LOG
from tests.vehicle.helpers import DB, SHIPPED, frame


class Sink:
    """A VehicleOutput that keeps everything."""

    def __init__(self) -> None:
        self.motions = Collector()
        self.drivers = Collector()
        self.statuses = Collector()
        self.served = threading.Event()

    def motion(self, msg) -> None:
        self.motions(msg, "vehicle/motion")

    def driver(self, msg) -> None:
        self.drivers(msg, "vehicle/driver")

    def status(self, msg) -> None:
        self.statuses(msg, "status")

    def serving(self) -> None:
        self.served.set()


def gateway(**fields):
    return msgspec.structs.replace(SHIPPED, **fields)


def test_the_sample_drive_replayed_fast_is_counted_frame_by_frame():
    g = gateway(can=CanSettings(interface="replay"),
                replay=ReplaySettings(file=str(LOG), pace=Pace.FAST, exit_at_end=True))
    out = Sink()
    shell = VehicleShell(g, VehicleCore(g, DB), out)
    assert shell.run(threading.Event()) == 0
    assert out.served.is_set()
    last = out.statuses.messages[-1]
    assert last.bus_state is BusState.ENDED and not last.ready
    assert last.not_ready_reason == "replay ended"
    assert (last.frames_total, last.frames_decoded) == (5070, 4029)
    assert last.rejected == {"decode_error": 1, "unmapped_gear:7": 1}
    assert last.ignored == {"not_in_dbc": 130, "no_mapped_signal": 910}
    assert last.interface == "replay" and last.dbc == "generic-car.dbc"
    assert sum(last.published.values()) == len(out.motions.messages) + len(
        out.drivers.messages)


def send_all(link: SlcanPtyLink, kph: float) -> None:
    frames = [frame("VehicleSpeed", VehicleSpeed=kph), frame("YawRate", YawRate=1.0),
              frame("SteeringWheel", SteeringWheelAngle=5.0), frame("Pedals"),
              frame("Brake"), frame("Gear", GearLever=3)]
    link.send([RadarFrame(arb, data) for arb, data in frames])


def test_a_bus_that_goes_silent_stops_the_messages_and_says_so(running):
    with SlcanPtyLink() as link:
        g = gateway(can=CanSettings(interface="slcan", channel=link.path,
                                    options={"sleep_after_open": 0}, silent_after_s=0.3),
                    status_period_s=0.2)
        out = Sink()
        running(VehicleShell(g, VehicleCore(g, DB), out))
        link.wait_open(30)
        feeding = threading.Event()
        feeding.set()
        stop_feed = threading.Event()

        def feed() -> None:
            while not stop_feed.wait(0.01):
                if feeding.is_set():
                    send_all(link, 18.0)

        feeder = threading.Thread(target=feed, daemon=True)
        feeder.start()
        try:
            ready = out.statuses.wait_until(lambda s: s.ready, 30)
            out.motions.wait_count(10, 30)
            feeding.clear()
            silent = out.statuses.wait_until(lambda s: s.bus_state is BusState.SILENT
                                             and s.header.seq > ready.header.seq, 30)
            assert not silent.ready
            assert silent.not_ready_reason == "no CAN frames received recently"
            assert silent.interface == "slcan" and silent.channel == link.path
            # silent after 0.3 s: the 0.1 s signals are stale, the gear (0.35 s) not yet
            fresh = {h.signal for h in silent.signals if h.fresh}
            assert fresh <= {"Gear.GearLever"}
            published = len(out.motions.messages)
            # silent for at least a status period more: nothing published meanwhile
            n = len(out.statuses.messages)
            wait_for(lambda: len(out.statuses.messages) >= n + 2, 30, what="two more status")
            assert len(out.motions.messages) == published
            assert out.statuses.messages[-1].withheld["vehicle/motion"] > 0
            feeding.set()
            back = out.statuses.wait_until(
                lambda s: s.ready and s.header.seq > silent.header.seq, 30)
            assert back.bus_state is BusState.ACTIVE
            wait_for(lambda: len(out.motions.messages) > published, 30, what="motion again")
            assert out.motions.messages[-1].speed_mps == pytest.approx(5.0)
        finally:
            stop_feed.set()
            feeder.join(5)


class ListPort:
    """A receive-only port of given messages, then the end of a replay."""

    def __init__(self, messages: list[can.Message]) -> None:
        self.messages = list(messages)
        self.ended = False

    def recv(self, timeout: float | None = None) -> can.Message | None:
        if self.messages:
            return self.messages.pop(0)
        self.ended = True
        return None

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        raise AssertionError("the gateway never writes to the car's bus")

    def shutdown(self) -> None:
        pass


def test_error_frames_remote_frames_and_a_failing_core_are_counted():
    arb, data = frame("VehicleSpeed", VehicleSpeed=10.0)
    messages = [can.Message(is_error_frame=True),
                can.Message(arbitration_id=arb, is_remote_frame=True, is_extended_id=False),
                can.Message(arbitration_id=arb, data=data, is_extended_id=False),
                can.Message(arbitration_id=arb, data=data, is_extended_id=False)]
    g = gateway(replay=ReplaySettings(exit_at_end=True))
    core = VehicleCore(g, DB)
    calls = []

    def fail_once(*args):
        calls.append(args)
        if len(calls) == 1:
            raise RuntimeError("a bug")
        VehicleCore.on_frame(core, *args)

    core.on_frame = fail_once   # type: ignore[method-assign]
    out = Sink()
    shell = VehicleShell(g, core, out, port_factory=lambda: ListPort(messages))
    assert shell.run(threading.Event()) == 0
    assert shell.bus_rejected.snapshot() == {"error_frame": 1, "remote_frame": 1,
                                             "internal_error": 1}
    assert len(calls) == 2 and core.frames_decoded == 1
    last = out.statuses.messages[-1]
    assert last.rejected == {"bus:error_frame": 1, "bus:remote_frame": 1,
                             "bus:internal_error": 1}
