"""Load a TOML file into a validated config type, with command-line overrides
(common/config/overrides.py); fail fast naming the field. Paths in the file are resolved
against its folder (common/config/paths.py)."""

import math
import sys
import tomllib
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import msgspec

from aeb_radar_camera.common.config.overrides import Override, OverrideError, apply_overrides
from aeb_radar_camera.common.config.paths import resolve_paths

T = TypeVar("T", bound=msgspec.Struct)


class ConfigError(ValueError):
    """An unreadable or invalid configuration; the message names the file and field."""


def parse_config(data: dict[str, Any], config_type: type[T], origin: str = "<config>") -> T:
    """Validate a mapping as `config_type` (paths stay as given). Raises ConfigError naming
    the offending field."""
    try:
        cfg = msgspec.convert(data, config_type, strict=True)
    except msgspec.ValidationError as exc:
        raise ConfigError(f"{origin}: invalid configuration: {exc}") from exc
    bad = first_unusable_number(cfg)
    if bad is not None:
        raise ConfigError(f"{origin}: invalid configuration: {bad[0]} is {bad[1]!r}: "
                          f"every number in a configuration must be finite and at most "
                          f"{MAX_MAGNITUDE:g} in magnitude")
    nul = first_value(cfg, lambda v: isinstance(v, str) and "\x00" in v)
    if nul is not None:
        # Any string may become a path, a key expression or a log line: the OS and Zenoh
        # would raise on it far from the file (a verifier's weights path: ValueError)
        raise ConfigError(f"{origin}: invalid configuration: {nul[0]} holds a NUL byte "
                          f"({nul[1]!r}): no setting may contain one")
    return cfg


# No setting needs more (a timeout of 1e9 s is 31 years); beyond, seconds in nanoseconds
# overflow float arithmetic and threading timeouts raise OverflowError.
MAX_MAGNITUDE = 1e9


def first_unusable_number(value: Any, where: str = "$") -> tuple[str, float] | None:
    """The path (``$.brake.deadline_ms``) and value of the first NaN, infinite or larger
    than `MAX_MAGNITUDE` float at any depth of a config (struct fields, tables, arrays),
    or None.

    No setting means "unlimited" by infinity: an `inf` or `nan` that passed a range check
    (``inf > 0``) would otherwise reach arithmetic that raises (``round(inf)``) or timers
    that never fire."""
    return first_value(value, lambda v: isinstance(v, float) and not (
        math.isfinite(v) and abs(v) <= MAX_MAGNITUDE), where)


def first_value(value: Any, bad: Callable[[Any], bool],
                where: str = "$") -> tuple[str, Any] | None:
    """The path and value of the first leaf of a config (struct fields, tables, arrays,
    at any depth) for which `bad` holds, or None."""
    if bad(value):
        return where, value
    if isinstance(value, msgspec.Struct):
        items: list[tuple[str, Any]] = [(f"{where}.{f}", getattr(value, f))
                                        for f in value.__struct_fields__]
    elif isinstance(value, dict):
        items = [(f"{where}.{k}", v) for k, v in value.items()]
    elif isinstance(value, (tuple, list)):
        items = [(f"{where}[{i}]", v) for i, v in enumerate(value)]
    else:
        return None
    for path, item in items:
        found = first_value(item, bad, path)
        if found is not None:
            return found
    return None


def read_toml(path: str | Path, what: str = "configuration") -> dict[str, Any]:
    """A TOML file's tables, not validated. Raises ConfigError naming the file: for one
    that cannot be read ("cannot read <what>") and for bad TOML."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read {what}: {exc.strerror}") from exc
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: not valid TOML: {exc}") from exc


def load_config(path: str | Path | None, config_type: type[T],
                overrides: Sequence[Override] = (), *, what: str = "configuration") -> T:
    """Read and validate a TOML file (None: the defaults) with `overrides` set in it;
    `what` it holds names it in errors; relative paths in the file are resolved against
    its folder. Raises ConfigError (missing file, bad TOML, bad field, an override naming
    no setting)."""
    data = {} if path is None else read_toml(path, what)
    origin = "<defaults>" if path is None else str(path)
    if overrides:
        try:
            data = apply_overrides(data, overrides, config_type)
        except OverrideError as exc:
            raise ConfigError(str(exc)) from exc
        origin += " with " + ", ".join(o.option for o in overrides)
    cfg = parse_config(data, config_type, origin)
    return cfg if path is None else resolve_paths(cfg, Path(path).resolve().parent)


def relocated_text(path: str | Path, config_type: type[T]) -> str:
    """The TOML text of a config file with each relative path in it (its `ConfigPath`
    values) made absolute, for a copy written into another folder (the simulator's run
    folder). Raises ConfigError like `load_config`."""
    p = Path(path)
    load_config(p, config_type)    # the same errors as loading it
    text = p.read_text(encoding="utf-8")
    pairs: list[tuple[str, str]] = []
    resolve_paths(parse_config(tomllib.loads(text), config_type, str(p)), p.resolve().parent,
                  pairs)
    for written, absolute in pairs:
        for quote in ('"', "'"):
            text = text.replace(f"{quote}{written}{quote}", f"{quote}{absolute}{quote}")
    return text


def load_config_or_exit(path: str | Path | None, config_type: type[T],
                        overrides: Sequence[Override] = ()) -> T:
    """For a service's main: the config (defaults when `path` is None) with `overrides`,
    or exit code 2."""
    try:
        return load_config(path, config_type, overrides)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from exc
