"""The PM QoS request that `bench_latency --cpu-latency-us` holds for a run."""

import os
import struct

import pytest

from aeb_radar_camera.common.cpu_latency import DEVICE, CpuLatencyRefused, cpu_latency


def _current_request_us() -> int:
    """The machine's current limit: reading the device gives the aggregate request."""
    fd = os.open(DEVICE, os.O_RDONLY)
    try:
        return int(struct.unpack("i", os.read(fd, 4))[0])
    finally:
        os.close(fd)


def test_the_value_is_written_as_the_kernel_reads_it(tmp_path):
    stand_in = tmp_path / "cpu_dma_latency"
    stand_in.write_bytes(b"")
    with cpu_latency(7, device=str(stand_in)):
        assert struct.unpack("i", stand_in.read_bytes()) == (7,)


def test_bad_values_and_missing_devices_are_clear_errors(tmp_path):
    with pytest.raises(ValueError, match=">= 0"), cpu_latency(-1, device=str(tmp_path)):
        pass
    with pytest.raises(CpuLatencyRefused, match="cannot open"), \
            cpu_latency(0, device=str(tmp_path / "missing")):
        pass


@pytest.mark.skipif(not os.access(DEVICE, os.R_OK | os.W_OK),
                    reason=f"{DEVICE} is missing or not writable here (PM QoS needs root); "
                           "the stand-in file test covers the write")
def test_the_request_holds_while_open_and_goes_with_the_block():
    before = _current_request_us()
    with cpu_latency(0):
        assert _current_request_us() == 0
    assert _current_request_us() == before
