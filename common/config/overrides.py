"""Command-line overrides of a configuration: `--set section.key=value`.

An override is set in the configuration's tables as read from TOML, before validation, so
that it is checked exactly as the file's own values are (`--check` refuses what a start
would). VALUE is read as a TOML value (``0.05``, ``true``, ``["a", "b"]``, ``"text"``),
else taken as text; a setting that only takes text (a name, a path, a choice) takes VALUE
as written. A path given on the command line is relative to the current directory, as
any command's paths are (common/config/paths.py).
"""

import argparse
import tomllib
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec
import msgspec.inspect as mi

from aeb_radar_camera.common.config.paths import PATH_KEYS_MARK, PATH_MARK, resolve_path


class OverrideError(ValueError):
    """An override naming no setting, or not of the form NAME=VALUE."""


@dataclass(frozen=True)
class Override:
    """One setting from the command line. `text`: VALUE as written; `value`: what it is set
    to before the setting's type is known (None: read `text` as a TOML value); `option`:
    how it was given, for errors (``--set fusion.instance=x``, ``--port /dev/ttyUSB0``)."""

    key: str
    text: str
    option: str
    value: Any = None

    @property
    def assignment(self) -> str:
        """``key=text``, as `--set` takes it."""
        return f"{self.key}={self.text}"


def parse_set(item: str) -> Override:
    """`NAME=VALUE` (a `--set` argument) as an override. Raises OverrideError."""
    name, sep, text = item.partition("=")
    name = name.strip()
    if not sep or not name or any(not part for part in name.split(".")):
        raise OverrideError(f"--set {item!r}: expected SECTION.KEY=VALUE")
    return Override(name, text, f"--set {item}")


def _set_argument(text: str) -> Override:
    try:
        return parse_set(text)
    except OverrideError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def add_set_argument(parser: argparse.ArgumentParser) -> None:
    """`--set SECTION.KEY=VALUE` (repeatable) into `args.overrides`, a list of Override;
    a malformed one is a usage error (exit 2)."""
    parser.add_argument("--set", action="append", dest="overrides", default=[],
                        type=_set_argument, metavar="SECTION.KEY=VALUE",
                        help="override one setting of the config (repeatable), e.g. "
                             "fusion.verifier.params.tau=0.05; VALUE is a TOML value or text")


def _toml_value(text: str) -> Any:
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _unwrap(info: mi.Type) -> tuple[mi.Type, dict[str, Any]]:
    """The type under its constraints, and the constraints' `extra` marks."""
    extra: dict[str, Any] = {}
    while isinstance(info, mi.Metadata):
        extra.update(info.extra or {})
        info = info.type
    return info, extra


def _takes_text_only(info: mi.Type) -> bool:
    base, _ = _unwrap(info)
    if isinstance(base, mi.UnionType):
        return all(_takes_text_only(t) for t in base.types if not isinstance(t, mi.NoneType))
    if isinstance(base, mi.EnumType):
        return all(isinstance(m.value, str) for m in base.cls)
    return isinstance(base, mi.StrType)


def _struct_for(info: mi.Type, table: Any) -> mi.StructType | None:
    """The struct a table is read as: the struct itself, or the member of a tagged union
    its tag names (the first member when the table names none)."""
    base, _ = _unwrap(info)
    if isinstance(base, mi.StructType):
        return base
    if isinstance(base, mi.UnionType):
        members = [t for t in (_unwrap(t)[0] for t in base.types) if isinstance(t, mi.StructType)]
        tagged = [m for m in members if isinstance(table, dict) and m.tag_field is not None
                  and table.get(m.tag_field) == m.tag]
        return next(iter(tagged or members), None)
    return None


def _value(o: Override, info: mi.Type, is_path: bool) -> Any:
    value = o.value if o.value is not None else _toml_value(o.text)
    if o.value is None and _takes_text_only(info) and not isinstance(value, str):
        value = o.text
    if not is_path:
        return value
    cwd = Path.cwd()
    if isinstance(value, str):
        return resolve_path(value, cwd)
    if isinstance(value, list):
        return [resolve_path(v, cwd) if isinstance(v, str) else v for v in value]
    return value


def _fields(struct: mi.StructType) -> dict[str, mi.Type]:
    fields = {f.encode_name: f.type for f in struct.fields}
    if struct.tag_field is not None:
        fields[struct.tag_field] = mi.StrType()
    return fields


def _set(data: dict[str, Any], o: Override, root: mi.StructType) -> None:
    """Set `o` in `data`, creating the tables on its way. Raises OverrideError."""
    parts = o.key.split(".")
    node: dict[str, Any] = data
    info: mi.Type = root
    path_keys: tuple[str, ...] = ()     # the keys of a parameter table that are paths
    for depth, part in enumerate(parts):
        where = ".".join(parts[:depth]) or "the configuration"
        struct = _struct_for(info, node)
        base = _unwrap(info)[0]
        if struct is not None:
            fields = _fields(struct)
            if part not in fields:
                raise OverrideError(f"{o.option}: {where} has no setting {part!r} (it has "
                                    f"{', '.join(sorted(fields))})")
            child = fields[part]
        elif isinstance(base, mi.DictType):
            child = base.value_type
        else:
            raise OverrideError(f"{o.option}: {where} is not a table of settings")
        if depth == len(parts) - 1:
            break
        table = node.setdefault(part, {})
        if not isinstance(table, dict):
            raise OverrideError(f"{o.option}: {'.'.join(parts[:depth + 1])} is not a table "
                                f"of settings")
        path_keys = tuple(_unwrap(child)[1].get(PATH_KEYS_MARK, ()))
        node, info = table, child
    base, extra = _unwrap(child)
    element = base.item_type if isinstance(base, mi.VarTupleType) else base
    is_path = bool(extra.get(PATH_MARK) or _unwrap(element)[1].get(PATH_MARK)) \
        or parts[-1] in path_keys
    node[parts[-1]] = _value(o, child, is_path)


def apply_overrides(data: dict[str, Any], overrides: Iterable[Override],
                    config_type: type[msgspec.Struct]) -> dict[str, Any]:
    """`data` (a configuration's tables, as read from TOML; not modified) with each
    override set, in order. Raises OverrideError naming the override when the
    configuration has no such setting or a name passes through a value."""
    out = _copy_tables(data)
    root = mi.type_info(config_type)
    assert isinstance(root, mi.StructType)
    for o in overrides:
        _set(out, o, root)
    return out


def _copy_tables(data: dict[str, Any]) -> dict[str, Any]:
    return {k: _copy_tables(v) if isinstance(v, dict) else v for k, v in data.items()}
