"""CAN test support: the real ARS408 recording, feeding frames into a radar core, and a
vcan interface when the kernel has one.

The radar side of a cross-process link (slcan pty, socketcand server) is
`tools.sim.can_links`, shared with the simulator.
"""

import functools
import subprocess
import uuid
from collections.abc import Iterable, Iterator
from contextlib import contextmanager

import can

from aeb_radar_camera.common.config.radar import RadarSettings
from aeb_radar_camera.common.resources import ARS408_RECORDING
from aeb_radar_camera.services.radar.ars408 import RadarFrame, classify
from aeb_radar_camera.services.radar.core import RadarCore, TrackedCycle
from aeb_radar_camera.services.radar.ports import radar_frame

RECORDING = ARS408_RECORDING
RECORDING_CYCLES = 515
RECORDING_FRAMES = 9579


@functools.cache
def recording_messages() -> tuple[can.Message, ...]:
    """Every frame of the real recording (read once per test session)."""
    return tuple(can.LogReader(str(RECORDING)))


def feed(core: RadarCore, frames: Iterable[tuple[RadarFrame, float]], mono_start: int = 0
         ) -> list[TrackedCycle]:
    """Frames (with their source time in s) through a core; mono time advances 1 us a frame."""
    out: list[TrackedCycle] = []
    for k, (frame, t_s) in enumerate(frames):
        found = classify(frame.arb_id)
        assert found is not None, f"test fed a non-ARS408 ID 0x{frame.arb_id:X}"
        out += core.on_frame(found[0], frame.data, t_s, int(t_s * 1e9), mono_start + 1000 * k)
    return out


def recording_frames() -> list[tuple[RadarFrame, float]]:
    return [(radar_frame(m), m.timestamp) for m in recording_messages()]


def run_recording(settings: RadarSettings | None = None) -> tuple[RadarCore, list[TrackedCycle]]:
    """The whole recording through one core, flushed at the end."""
    s = settings or RadarSettings()
    core = RadarCore(s.sensors[0], s)
    results = feed(core, recording_frames())
    return core, results + core.flush()


class VcanUnavailable(RuntimeError):
    """The kernel cannot create a vcan interface (no vcan module, no permission)."""


@contextmanager
def vcan_interface() -> Iterator[str]:
    """A fresh vcan interface, deleted afterwards. Raises VcanUnavailable with the
    kernel's reason when it cannot be created."""
    name = f"vcan{uuid.uuid4().hex[:6]}"
    try:
        made = subprocess.run(["ip", "link", "add", "dev", name, "type", "vcan"],
                              capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise VcanUnavailable(f"cannot run ip: {exc}") from exc
    if made.returncode != 0:
        raise VcanUnavailable(f"ip link add type vcan: {made.stderr.strip() or made.returncode}")
    try:
        subprocess.run(["ip", "link", "set", "up", name], check=True, timeout=10)
        yield name
    finally:
        subprocess.run(["ip", "link", "delete", name], capture_output=True, timeout=10)


