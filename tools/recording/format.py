"""The recording format, fixed for every tool that reads or writes a drive.

MCAP files (mcap.dev). One channel per Zenoh key:

- topic = the full key (``aeb/ego/radar/front/tracks``);
- message encoding ``msgpack``: the payload exactly as it was on the bus;
- schema ``aeb.<MessageType>`` (the name in the samples' Zenoh encoding), encoding
  ``jsonschema``, data = msgspec's JSON schema of the type (common/messages/schema.py),
  so that a generic tool can decode every channel;
- log_time = the recorder's wall-clock receive time (ns); publish_time = the message's
  `header.stamp_ns` (when the data was measured), the log time when it has no header.

Beside them, channels derived for viewing (tools/recording/foxglove_views.py), under
``/foxglove/<vehicle>/...``: Foxglove schemas in protobuf (CompressedImage,
ImageAnnotations, SceneUpdate) and small JSON channels (plots, health). Readers of the
stack's own data use the msgpack channels only.
"""

import re
from dataclasses import dataclass
from typing import Any

import msgspec

from aeb_radar_camera.common.keys import KeySpec
from aeb_radar_camera.common.messages.schema import json_schema, schema_name
from aeb_radar_camera.tools.keys import MESSAGE_KEYS

MESSAGE_ENCODING = "msgpack"
SCHEMA_ENCODING = "jsonschema"
DERIVED_PREFIX = "/foxglove/"
# Metadata record written at the start of every file of a recording.
METADATA_NAME = "aeb.recording"

_TOPIC = re.compile(r"^aeb/(?P<vehicle>[^/]+)/(?P<rest>.+)$")


@dataclass(frozen=True, slots=True)
class ChannelType:
    """What a channel carries: MCAP schema name, schema encoding and data, and the
    message encoding."""

    schema_name: str
    schema_encoding: str
    schema_data: bytes
    message_encoding: str


_STACK_CHANNELS: dict[type[Any], ChannelType] = {}


def stack_channel(msg_type: type[msgspec.Struct]) -> ChannelType:
    """The channel type of a stack message (msgpack with its JSON schema)."""
    kind = _STACK_CHANNELS.get(msg_type)
    if kind is None:
        schema = msgspec.json.encode(json_schema(msg_type))
        kind = _STACK_CHANNELS[msg_type] = ChannelType(
            schema_name(msg_type), SCHEMA_ENCODING, schema, MESSAGE_ENCODING)
    return kind


# A key no tool knows (another version's, a user's own): recorded as it was, msgpack
# assumed, without a schema.
UNKNOWN_CHANNEL = ChannelType("", "", b"", MESSAGE_ENCODING)


@dataclass(frozen=True, slots=True)
class TopicInfo:
    """A stack topic parsed: its vehicle, its spec and the spec's parameters."""

    vehicle: str
    spec: KeySpec[Any]
    params: dict[str, str]


def parse_topic(topic: str) -> TopicInfo | None:
    """The known spec of a stack topic (a Zenoh key), or None (a derived topic, or a key
    no spec matches)."""
    m = _TOPIC.match(topic)
    if m is None:
        return None
    vehicle = m.group("vehicle")
    for spec in MESSAGE_KEYS:
        params = spec.match(topic, vehicle)
        if params is not None:
            return TopicInfo(vehicle, spec, params)
    return None


def channel_of_topic(topic: str) -> ChannelType:
    info = parse_topic(topic)
    if info is None or info.spec.msg_type is None:
        return UNKNOWN_CHANNEL
    return stack_channel(info.spec.msg_type)


class _Stamped(msgspec.Struct):
    """Just the header's stamp of any stack message (the rest is skipped, not decoded)."""

    header: "_Stamp"


class _Stamp(msgspec.Struct):
    stamp_ns: int


_stamp_decoder = msgspec.msgpack.Decoder(_Stamped)


def publish_time(payload: bytes, default_ns: int) -> int:
    """A stack payload's `header.stamp_ns`, or `default_ns` when it has none (or does
    not decode: it is recorded all the same)."""
    try:
        return _stamp_decoder.decode(payload).header.stamp_ns
    except (msgspec.DecodeError, msgspec.ValidationError):
        return default_ns


def missed_between(last_seq: int | None, seq: int) -> int:
    """Messages a publisher numbered between the last one seen (`last_seq`) and this one
    that never arrived: what a recording calls dropped. 0 for the first, and after a
    restart (numbers starting again)."""
    return seq - last_seq - 1 if last_seq is not None and seq > last_seq + 1 else 0
