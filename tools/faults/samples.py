"""A valid example of every message type on the bus, built from the type alone (so that
a message added later is covered by whatever iterates over them: the fuzzers, the
schema tests)."""

import enum
import types
import typing
from typing import Any

import msgspec

from aeb_radar_camera.common.messages import SCHEMA_VERSION
from aeb_radar_camera.tools.keys import MESSAGE_KEYS


def message_types() -> list[type[msgspec.Struct]]:
    """The message type of every key (the registry's and the simulator's), once each."""
    seen: dict[str, type[msgspec.Struct]] = {}
    for spec in MESSAGE_KEYS:
        assert spec.msg_type is not None
        seen.setdefault(spec.msg_type.__name__, spec.msg_type)
    return list(seen.values())


def example(tp: Any, depth: int = 0) -> Any:
    """A value of annotation `tp` that the type accepts."""
    origin = typing.get_origin(tp)
    if origin is typing.Annotated:
        return example(typing.get_args(tp)[0], depth)
    if origin in (typing.Union, types.UnionType):
        return example(next(a for a in typing.get_args(tp) if a is not type(None)), depth)
    if origin is tuple:
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return (example(args[0], depth + 1),)
        return tuple(example(a, depth + 1) for a in args)
    if origin in (dict, typing.Dict):  # noqa: UP006 (typing.Dict is what get_origin may give)
        return {"a": example(typing.get_args(tp)[1], depth + 1)}
    if origin in (list, typing.List):  # noqa: UP006
        return [example(typing.get_args(tp)[0], depth + 1)]
    if isinstance(tp, type) and issubclass(tp, msgspec.Struct):
        values = {f.name: example(f.type, depth + 1) for f in msgspec.structs.fields(tp)}
        if "schema" in values:
            values["schema"] = SCHEMA_VERSION
        return tp(**values)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return next(iter(tp))
    return {bool: True, int: 7, float: 1.5, str: "x", bytes: b"\xff\xd8"}[tp]
