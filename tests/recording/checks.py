"""What a recording of the stack must be, checked as a generic tool would read it: the
`mcap` package's reader, each channel's own schema, and no knowledge of our types beyond
the key registry."""

import json
from pathlib import Path
from typing import Any

import jsonschema
import msgspec
from mcap.reader import make_reader

from aeb_radar_camera.common.keys import CAMERA_DEPTH, REGISTRY, VEHICLE_DRIVER, VEHICLE_STATUS
from tests.foxglove.protobuf import message_class

# Every key of the registry that carries messages (liveliness tokens are not samples),
# but depth (only a camera whose source has depth publishes it) and the vehicle
# gateway's (the simulated stack runs no gateway: the simulator publishes vehicle/motion).
STACK_SPECS = {s.name for s in REGISTRY.values()
               if s.msg_type is not None
               and s not in (CAMERA_DEPTH, VEHICLE_DRIVER, VEHICLE_STATUS)}


def check_recording(path: Path) -> dict[str, Any]:
    """Decode every message of every channel with the schema the file gives it (JSON
    schema for the stack's msgpack channels, after a generic msgpack decode; protobuf for
    the Foxglove views; JSON schema for the JSON views). Returns {topic: (schema name,
    message count)} and the decoded Foxglove views by schema name. Raises AssertionError
    (or the validator's error) on the first message that does not match its schema."""
    views: dict[str, list[Any]] = {}
    counts: dict[str, tuple[str, int]] = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        validators: dict[int, Any] = {}
        for schema, channel, message in reader.iter_messages():
            assert schema is not None, f"{channel.topic} has no schema"
            if schema.id not in validators:
                if schema.encoding == "jsonschema":
                    validators[schema.id] = jsonschema.Draft202012Validator(
                        json.loads(schema.data))
                else:
                    assert schema.encoding == "protobuf", schema.encoding
                    validators[schema.id] = message_class(schema.name, schema.data)
            check = validators[schema.id]
            if channel.message_encoding == "msgpack":
                generic = msgspec.msgpack.decode(message.data)     # no type: any tool
                check.validate(json.loads(msgspec.json.encode(generic)))
            elif channel.message_encoding == "json":
                check.validate(json.loads(message.data))
            else:
                assert channel.message_encoding == "protobuf"
                views.setdefault(schema.name, []).append(check.FromString(message.data))
            name, n = counts.get(channel.topic, (schema.name, 0))
            counts[channel.topic] = (name, n + 1)
    return {"channels": counts, "views": views}


def stamp_ns(ts: Any) -> int:
    return ts.seconds * 1_000_000_000 + ts.nanos
