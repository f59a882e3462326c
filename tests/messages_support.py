"""Every message type on the bus, and a valid example of any of them, built from the
type alone (so that a message added later is covered by the tests that iterate)."""

from aeb_radar_camera.tools.faults.samples import example, message_types

__all__ = ["example", "message_types"]
