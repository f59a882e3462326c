"""The header every message carries."""

import msgspec

SCHEMA_VERSION = 1


class Header(msgspec.Struct, frozen=True, gc=False):
    """Common header.

    `seq` increases by one per message on a key; `source` names the publishing service
    instance (e.g. ``radar/front``); `stamp_ns` is the wall-clock time the data was
    measured; `pub_mono_ns` is the publisher's monotonic clock at publish time, for
    same-host latency.
    """

    seq: int
    source: str
    stamp_ns: int
    pub_mono_ns: int
    schema: int = SCHEMA_VERSION
