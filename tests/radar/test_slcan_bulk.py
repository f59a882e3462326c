"""The bulk slcan reader (common/slcan_bulk.py) on a real pty: whole bursts in one
read, lines cut in two, noise counted and skipped, a port that vanishes, an idle wait
that blocks instead of polling; and the radar service counting what it dropped."""

import contextlib
import time
from collections.abc import Iterator

import can
import pytest

from aeb_radar_camera.common.config.radar import CanSettings, Expect, RadarSettings, ReplaySettings
from aeb_radar_camera.common.slcan_bulk import MAX_LINE, BulkSlcanBus
from aeb_radar_camera.services.radar.ars408 import ObjectGeneral, RadarFrame, object_cycle_frames
from aeb_radar_camera.services.radar.ports import open_port, radar_frame
from aeb_radar_camera.services.radar.shell import RadarShell
from aeb_radar_camera.tools.sim.can_links import SlcanPtyLink, slcan_line
from tests.radar.test_shell import Output
from tests.support import wait_for


@pytest.fixture
def link_bus() -> Iterator[tuple[SlcanPtyLink, BulkSlcanBus]]:
    with SlcanPtyLink() as link:
        bus = BulkSlcanBus(link.path, bitrate=500_000, sleep_after_open=0)
        try:
            link.wait_open(10)
            yield link, bus
        finally:
            with contextlib.suppress(can.CanError):   # the link may be gone already
                bus.shutdown()


def recv_all(bus: can.BusABC, n: int, timeout_s: float = 5.0) -> list[can.Message]:
    out: list[can.Message] = []
    deadline = time.monotonic() + timeout_s
    while len(out) < n and time.monotonic() < deadline:
        m = bus.recv(0.2)
        if m is not None:
            out.append(m)
    return out


def frames_of(msgs: list[can.Message]) -> list[RadarFrame]:
    return [radar_frame(m) for m in msgs]


def test_a_whole_cycle_written_at_once_comes_out_complete_and_in_order(link_bus):
    link, bus = link_bus
    frames = object_cycle_frames(
        [ObjectGeneral(i, 5.0 + i, 0.2 * i, -1.0, 0.0, 0, 4.0) for i in range(40)], 7)
    link.send(frames)
    got = recv_all(bus, len(frames))
    assert frames_of(got) == frames
    assert all(not m.is_extended_id and not m.is_remote_frame for m in got)
    assert bus.line_errors.total() == 0


def test_a_line_cut_in_two_waits_for_its_second_half(link_bus):
    link, bus = link_bus
    line = slcan_line(RadarFrame(0x60B, bytes(range(8))))
    link.send_raw(line[:9])
    assert bus.recv(0.1) is None
    link.send_raw(line[9:])
    m = bus.recv(2.0)
    assert m is not None and (m.arbitration_id, bytes(m.data)) == (0x60B, bytes(range(8)))


def test_noise_is_counted_and_skipped_and_replies_are_not_noise(link_bus):
    link, bus = link_bus
    good = RadarFrame(0x60A, b"\x01\x00\x07\x10")
    link.send_raw(b"\r" + b"z\r"                 # adapter replies: ignored, not counted
                  + b"tXYZ8001122334455667\r"    # bad hex
                  + b"t60B8AABB\r"               # DLC 8, one byte of data
                  + b"Q12345\r"                  # no such command
                  + b"t60\xff\xfe\r"             # not ASCII
                  + b"x" * (MAX_LINE + 10)       # a run with no terminator
                  + b"\r" + slcan_line(good))
    got = recv_all(bus, 1)
    assert frames_of(got) == [good]
    errors = bus.line_errors.snapshot()
    assert errors == {"malformed": 1, "length": 1, "unknown": 1, "not_ascii": 1,
                      "too_long": 1}


def test_a_port_that_vanishes_raises_can_operation_error(link_bus):
    link, bus = link_bus
    link.close()
    with pytest.raises(can.CanOperationError):
        for _ in range(50):
            bus.recv(0.1)


def test_waiting_blocks_in_select_instead_of_polling(link_bus):
    _, bus = link_bus
    cpu0, t0 = time.thread_time(), time.monotonic()
    assert bus.recv(0.3) is None
    waited, cpu = time.monotonic() - t0, time.thread_time() - cpu0
    assert waited >= 0.29
    # python-can's reader polls every millisecond (about 300 wake-ups here)
    assert cpu < 0.02, f"{cpu * 1e3:.1f} ms of CPU for a 300 ms wait"


def test_open_port_opens_slcan_with_the_bulk_reader():
    with SlcanPtyLink() as link:
        settings = CanSettings(interface="slcan", channel=link.path,
                               options={"sleep_after_open": 0})
        bus = open_port(settings, ReplaySettings())
        try:
            assert isinstance(bus, BulkSlcanBus)
        finally:
            bus.shutdown()


def test_the_service_reports_dropped_lines_in_its_status(running):
    with SlcanPtyLink() as link:
        settings = RadarSettings(can=CanSettings(
            interface="slcan", channel=link.path, options={"sleep_after_open": 0}))
        settings = RadarSettings(can=settings.can, cycle=type(settings.cycle)(
            expect_quality=Expect.NO, expect_extended=Expect.NO))
        out = Output()
        running(RadarShell(settings, out))
        link.wait_open(10)
        link.send_raw(b"tXYZ8001122334455667\r")
        for k in range(3):
            link.send(object_cycle_frames([ObjectGeneral(1, 12.0, 0.4, -2.0, 0.0, 0, 10.0)], k))
        out.got_tracks.wait_count(2, 30)
        st = out.status_where(lambda s: s.rejected.get("bus:slcan_malformed") == 1)
        assert st.rejected["bus:slcan_malformed"] == 1
        wait_for(lambda: out.got_tracks.messages, 5)
