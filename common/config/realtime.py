"""Scheduling of the threads on the radar-to-brake path: the `realtime` table of the
radar, fusion and brake configurations (`[radar.realtime]`, `[brake.realtime]`, ...).

See common/realtime.py for what is applied and docs/deploy.md for when to enable it.
"""

from typing import Annotated

import msgspec


class RealtimeSettings(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """`priority` 1..99: SCHED_FIFO for the service's threads on the latency path (its
    main loop or its Zenoh callbacks) and, with `zenoh_threads`, for its Zenoh receive and
    transmit threads; 0 keeps normal scheduling. Needs root or CAP_SYS_NICE; refused, the
    service logs a warning and runs with normal scheduling.

    `other_threads`: the process's other threads (frame decoders, timers, serial readers,
    zenoh-python's callback threads) get `priority - 1`: below the latency path, above
    the rest of the machine, so that none is preempted while it holds the GIL that the
    latency path waits for.

    `freeze_gc`: once started, move every object allocated so far out of the garbage
    collector's reach (gc.freeze), so that full collections stay short."""

    priority: Annotated[int, msgspec.Meta(ge=0, le=99)] = 0
    zenoh_threads: bool = True
    other_threads: bool = True
    freeze_gc: bool = True
