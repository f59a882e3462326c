"""How a message type is named on the wire and described to generic tools.

Every sample carries the Zenoh encoding ``application/msgpack;aeb.<Type>`` (common/bus.py),
the same schema name that recordings use, so that `z_sub`, a Zenoh bridge or a recorder
can tell what a payload is; `json_schema` is msgspec's JSON Schema of the type
(`aeb schemas` exports every one).

Schema evolution (docs/architecture.md): messages are msgpack maps keyed by field name
and unknown fields are ignored, so a newer publisher may add a field with a default and
an older subscriber still decodes it. Anything else (remove, rename, retype, change a
unit, a new enum value) is a breaking change: it bumps SCHEMA_VERSION, which older
subscribers reject (counted) instead of misreading.
"""

from typing import Any

import msgspec

MESSAGE_ENCODING = "application/msgpack"
_PREFIX = "aeb."


def schema_name(msg_type: type[msgspec.Struct]) -> str:
    """``aeb.<Type>``, e.g. ``aeb.RadarTracks``."""
    return _PREFIX + msg_type.__name__


def zenoh_encoding(msg_type: type[msgspec.Struct]) -> str:
    """The Zenoh encoding of a message type's samples."""
    return f"{MESSAGE_ENCODING};{schema_name(msg_type)}"


def json_schema(msg_type: type[msgspec.Struct]) -> dict[str, Any]:
    return msgspec.json.schema(msg_type)
