"""Linux's PM QoS CPU latency request (/dev/cpu_dma_latency), held for a `with` block:
by `aeb up` for a table with `cpu_latency_us` (docs/deploy.md) and by
`bench_latency --cpu-latency-us`.

While a process keeps the device open with a value written, no CPU enters an idle state
whose exit latency is above that many microseconds; 0 keeps idle CPUs polling, so that a
woken thread runs at once instead of waiting for its CPU to leave a sleep state (on a VM,
for the hypervisor to run the halted virtual CPU again). It costs power (or, on a VM, the
host's CPU time): a deployment choice.
"""

import os
import struct
from collections.abc import Iterator
from contextlib import contextmanager

DEVICE = "/dev/cpu_dma_latency"


class CpuLatencyRefused(OSError):
    """The request could not be made (no such device, or no permission: root only)."""


@contextmanager
def cpu_latency(max_us: int, device: str | None = None) -> Iterator[None]:
    """Hold the request for the `with` block (`device`: DEVICE unless given). Raises
    ValueError for a negative value and CpuLatencyRefused when the device cannot be
    opened or written."""
    device = DEVICE if device is None else device
    if max_us < 0:
        raise ValueError(f"cpu latency must be >= 0 us, got {max_us}")
    try:
        fd = os.open(device, os.O_WRONLY)
    except OSError as exc:
        raise CpuLatencyRefused(f"cannot open {device}: {exc}") from exc
    try:
        try:
            os.write(fd, struct.pack("i", max_us))
        except OSError as exc:
            raise CpuLatencyRefused(f"cannot write {device}: {exc}") from exc
        yield
    finally:
        os.close(fd)     # the kernel drops the request with the last close
