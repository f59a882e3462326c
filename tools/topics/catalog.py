"""Which message a sample carries: every key with a message (the registry's and the
simulator's), looked up by the sample's encoding (``application/msgpack;aeb.<Type>``) or,
for a publisher that sets none, by its key."""

from typing import Any

import msgspec

from common.keys import ROOT, KeySpec
from common.messages.schema import MESSAGE_ENCODING, schema_name
from tools.keys import MESSAGE_KEYS


class Catalog:
    def __init__(self, vehicle: str) -> None:
        self.vehicle = vehicle
        self.keys = MESSAGE_KEYS
        self.by_schema: dict[str, type[msgspec.Struct]] = {}
        for spec in self.keys:
            assert spec.msg_type is not None
            self.by_schema.setdefault(schema_name(spec.msg_type), spec.msg_type)

    def expression(self, text: str) -> str:
        """A key expression from what a user types: a registry name (``radar_tracks``), a
        key under ``aeb/<vehicle>/`` (``radar/front/tracks``, ``fusion/*/brake_cmd``,
        ``**``) or a full key (``aeb/ego/...``)."""
        for spec in self.keys:
            if text == spec.name:
                return spec.wildcard(self.vehicle)
        if text == ROOT or text.startswith(ROOT + "/"):
            return text
        return f"{ROOT}/{self.vehicle}/{text.strip('/')}"

    def spec_of(self, key: str) -> KeySpec[Any] | None:
        for spec in self.keys:
            if spec.match(key, self.vehicle) is not None:
                return spec
        return None

    def type_of(self, key: str, encoding: str) -> type[msgspec.Struct] | None:
        """The message type of a sample: its encoding's schema, else its key's."""
        kind, _, schema = encoding.partition(";")
        if kind == MESSAGE_ENCODING and schema in self.by_schema:
            return self.by_schema[schema]
        spec = self.spec_of(key)
        return None if spec is None else spec.msg_type

    def relative(self, key: str) -> str:
        """`key` without the ``aeb/<vehicle>/`` prefix."""
        return key.removeprefix(f"{ROOT}/{self.vehicle}/")
