"""The links and processing times the lockstep loop models, as constants: what the
services' processes and the transport between them add on a real host, here a fixed
delay per hop. From the figures in docs/performance.md (2-core VM): radar per cycle
0.48 ms (median), one bare Zenoh hop 0.36 ms (the two bare hops 0.72 ms), brake command
receipt to serial write 0.22 ms; fusion's share is what the radar-to-brake chain's p50
(2.14 ms) leaves. The camera's frame reaches fusion after the simulated camera rendered
it (the source stamps a frame, then renders it: 8-12 ms with the roadside and its
depth, docs/simulator.md), the camera service encoded and published it (capture to
subscriber 6.0 ms p50) and fusion decoded it (about 1.5 ms).
"""

from dataclasses import dataclass

MS = 1_000_000


@dataclass(frozen=True)
class Delays:
    """Nanoseconds each."""

    can_link_ns: int = 100_000           # a CAN frame written -> the radar service has it
    radar_ns: int = 480_000              # a cycle's last frame -> its tracks published
    zenoh_hop_ns: int = 360_000          # publish -> the subscriber's callback
    fusion_ns: int = 520_000             # tracks received -> the command published
    brake_ns: int = 220_000              # a command (or an actuator line) -> the line written
    serial_ns: int = 100_000             # a line written -> read at the other end
    camera_frame_ns: int = 18 * MS       # capture stamp -> the frame in fusion's ring

    @property
    def radar_to_brake_ns(self) -> int:
        """The last CAN frame of a cycle -> its command line on the actuator."""
        return (self.can_link_ns + self.radar_ns + 2 * self.zenoh_hop_ns + self.fusion_ns
                + self.brake_ns + self.serial_ns)
