"""Which message a sample carries: every key with a message (the registry's and the
simulator's), looked up by the sample's encoding (``application/msgpack;aeb.<Type>``) or,
for a publisher that sets none, by its key."""

import difflib
from typing import Any

import msgspec
import zenoh

from aeb_radar_camera.common.keys import ROOT, KeySpec
from aeb_radar_camera.common.messages.schema import MESSAGE_ENCODING, schema_name
from aeb_radar_camera.tools.keys import MESSAGE_KEYS


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

    def known(self, expr: str) -> bool:
        """Whether a key expression can match a key of the tools' registry."""
        try:
            wanted = zenoh.KeyExpr(expr)
        except zenoh.ZError:
            return False
        return any(wanted.intersects(zenoh.KeyExpr(spec.wildcard(self.vehicle)))
                   for spec in self.keys)

    def suggest(self, text: str, n: int = 2) -> list[str]:
        """The registry's keys nearest to what a user typed (a misspelt key), each once:
        `radar/front/tracks (radar_tracks)`, or the name when the name was typed."""
        rel = self.relative(text.strip("/"))
        typed = rel.split("/")
        candidates: dict[str, tuple[str, str]] = {}      # candidate -> (spec, shown)
        for spec in self.keys:
            candidates[spec.name] = (spec.name, spec.name)
            parts = spec.pattern.split("/")
            if len(parts) == len(typed):
                # the parameters as typed: radar/front/trakcs -> radar/front/tracks
                filled = "/".join(t if _is_param(p) else p
                                  for p, t in zip(parts, typed, strict=True))
                candidates[filled] = (spec.name, f"{filled} ({spec.name})")
        out: dict[str, str] = {}
        for close in difflib.get_close_matches(rel, list(candidates), n=len(candidates),
                                               cutoff=0.6):
            spec_name, shown = candidates[close]
            out.setdefault(spec_name, shown)
        return list(out.values())[:n]


def _is_param(part: str) -> bool:
    return part.startswith("{") and part.endswith("}")
