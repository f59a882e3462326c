"""The radar side of cross-process CAN links, against python-can's real interfaces."""

import threading

import can
import pytest

from aeb_radar_camera.services.radar.ars408 import ObjectGeneral, RadarFrame, object_cycle_frames
from aeb_radar_camera.services.radar.ports import radar_frame
from aeb_radar_camera.tools.sim.can_links import (
    SlcanPtyLink,
    SocketcandServer,
    parse_slcan_frame,
    parse_socketcand_send,
    replay_log,
    slcan_line,
)
from tests.can_support import RECORDING, RECORDING_FRAMES

CYCLE = object_cycle_frames([ObjectGeneral(1, 12.0, 0.4, -3.0, 0.0, 0, 10.0)], 7)


def recv_all(bus: can.BusABC, n: int) -> list[RadarFrame]:
    out: list[RadarFrame] = []
    while len(out) < n:
        m = bus.recv(10)
        assert m is not None, f"received {len(out)} of {n} frames"
        out.append(radar_frame(m))
    return out


def test_slcan_pty_link_both_directions():
    answered = threading.Event()
    with SlcanPtyLink(on_frame=lambda f: answered.set()) as link:
        bus = can.Bus(interface="slcan", channel=link.path, bitrate=500000, sleep_after_open=0)
        try:
            link.wait_open(10)
            link.send([*CYCLE, RadarFrame(0x123, b"")])
            assert recv_all(bus, 3) == [*CYCLE, RadarFrame(0x123, b"")]
            bus.send(can.Message(arbitration_id=0x200, data=bytes(range(8)),
                                 is_extended_id=False))
            assert link.wait_frame(lambda f: f.arb_id == 0x200, 10).data == bytes(range(8))
            assert answered.wait(10)
            assert link.commands[:2] == ["C", "S6"] and "O" in link.commands
        finally:
            bus.shutdown()


def test_socketcand_server_both_directions():
    with SocketcandServer() as server:
        bus = can.Bus(interface="socketcand", channel="can0", host=server.host,
                      port=server.port)
        try:
            server.wait_open(10)
            server.send(CYCLE)
            assert recv_all(bus, 2) == CYCLE
            bus.send(can.Message(arbitration_id=0x300, data=b"\x40\x10", is_extended_id=False))
            assert server.wait_frame(lambda f: f.arb_id == 0x300, 10).data == b"\x40\x10"
            assert server.commands == ["< open can0 >", "< rawmode >"]
        finally:
            bus.shutdown()


def test_replay_log_fast_sends_every_frame():
    sent: list[RadarFrame] = []
    assert replay_log(str(RECORDING), sent.extend, pace="fast") == RECORDING_FRAMES
    assert sent[0] == RadarFrame(0x60A, bytes.fromhex("03FBF710"))
    limited: list[RadarFrame] = []
    n = replay_log(str(RECORDING), limited.extend, pace="fast", loop=True,
                   max_duration_s=60.0)
    assert n > RECORDING_FRAMES                  # 37.9 s of log, looped to 60 s


def test_wire_formats():
    assert slcan_line(RadarFrame(0x60B, bytes.fromhex("204FEC00802001B4"))) == \
        b"t60B8204FEC00802001B4\r"
    assert parse_slcan_frame("t2008" + "00" * 8) == RadarFrame(0x200, bytes(8))
    assert parse_slcan_frame("S6") is None and parse_slcan_frame("tXYZ1") is None
    assert parse_socketcand_send("< send 2a0 3 b 4a e0 >") == RadarFrame(0x2A0, b"\x0b\x4a\xe0")
    assert parse_socketcand_send("< open can0 >") is None


def test_closed_link_refuses_to_send():
    link = SlcanPtyLink()
    link.close()
    link.close()
    with pytest.raises(OSError):
        link.send(CYCLE)


def test_a_links_received_frames_are_bounded_and_the_newest_still_found():
    """A soak's hours of forwarded ego motion must not pile up: the link keeps the
    newest FRAMES_KEPT frames (each one more object for every garbage collection)."""
    from aeb_radar_camera.tools.sim import can_links

    with SlcanPtyLink() as link:
        for i in range(can_links.FRAMES_KEPT + 500):
            link._got(RadarFrame(0x300, i.to_bytes(4, "big")))
        kept = link.received()
        assert len(kept) <= can_links.FRAMES_KEPT
        assert kept[-1].data == (can_links.FRAMES_KEPT + 499).to_bytes(4, "big")
        newest = link.wait_frame(lambda f: f.data == kept[-1].data, 1)
        assert newest == kept[-1]
