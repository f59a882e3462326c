"""Scheduling of the threads on the radar-to-brake path: the `realtime` table of the
radar, fusion and brake configurations (`[radar.realtime]`, `[brake.realtime]`, ...).

See common/realtime.py for what is applied and docs/deploy.md for when to enable it.
"""

from typing import Annotated

import msgspec


class RealtimeSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """`priority` 1..99: SCHED_FIFO for the service's threads on the latency path (its
    main loop or its Zenoh callbacks) and its Zenoh receive and transmit threads, and
    `priority - 1` for its other threads; 0 keeps normal scheduling. Needs root or
    CAP_SYS_NICE; refused, the service logs a warning and runs with normal scheduling."""

    priority: Annotated[int, msgspec.Meta(ge=0, le=99)] = 0
