"""read_available on a real pty: everything waiting in one call, nothing after a timeout,
an error once the other end is gone."""

import os
import time

import pytest
import serial

from aeb_radar_camera.common.serial_read import read_available


def test_reads_all_waiting_bytes_times_out_empty_and_fails_when_the_other_end_goes():
    master, slave = os.openpty()
    port = serial.Serial(os.ttyname(slave), 115200, timeout=0.05)
    try:
        os.write(master, b"A,1*00\nA,2*00\n")
        deadline = time.monotonic() + 10
        got = b""
        while len(got) < 14 and time.monotonic() < deadline:
            got += read_available(port, 1.0)
        assert got == b"A,1*00\nA,2*00\n"
        t0 = time.monotonic()
        assert read_available(port, 0.05) == b""
        assert time.monotonic() - t0 >= 0.04
        os.close(master)
        master = -1
        with pytest.raises(OSError):   # EIO from the pty, or PortGone
            for _ in range(100):
                read_available(port, 0.05)
    finally:
        port.close()
        os.close(slave)
        if master >= 0:
            os.close(master)
