"""Paths inside a configuration file are relative to the file's own folder, so that a
config works from any current directory and a copied deploy/ folder stays whole.

A config type marks a field as a path with `ConfigPath`, or the entries of a parameter
table that are paths with `path_keys(...)` (a verifier's `weights`); `load_config`
resolves every marked field of a file it reads (`resolve_paths`). Left as written: empty
values, absolute paths, URLs (``rtsp://...``) and device indexes (``"0"``). ``~`` is
expanded. Paths given on a command line stay relative to the current directory, as any
command's do.
"""

import os
from pathlib import Path
from typing import Annotated, Any, TypeVar

import msgspec

PATH_MARK = "aeb_config_path"
# No path holds a NUL byte: refused as a bad field here, not as a ValueError from the OS
# call that would meet it first
ConfigPath = Annotated[str, msgspec.Meta(pattern="^[^\x00]*$", extra={PATH_MARK: True})]
# A table of free parameters (a verifier's) whose entries under these keys are paths.
PATH_KEYS_MARK = "aeb_config_path_keys"


def path_keys(*keys: str) -> msgspec.Meta:
    """Mark a dict field: its string values under `keys` are paths (resolved as
    `ConfigPath` fields are)."""
    return msgspec.Meta(extra={PATH_KEYS_MARK: keys})

S = TypeVar("S", bound=msgspec.Struct)


def _is_path(annotation: Any) -> bool:
    return any(isinstance(m, msgspec.Meta) and (m.extra or {}).get(PATH_MARK)
               for m in getattr(annotation, "__metadata__", ()))


def _is_path_tuple(annotation: Any) -> bool:
    """`tuple[ConfigPath, ...]` (possibly Annotated itself)."""
    inner = getattr(annotation, "__origin__", None)
    if inner is not None and getattr(annotation, "__metadata__", None):
        annotation = inner
    args: tuple[Any, ...] = getattr(annotation, "__args__", ())
    return getattr(annotation, "__origin__", None) is tuple and len(args) > 0 \
        and _is_path(args[0])
def _keys(annotation: Any) -> tuple[str, ...]:
    for m in getattr(annotation, "__metadata__", ()):
        if isinstance(m, msgspec.Meta) and (m.extra or {}).get(PATH_KEYS_MARK):
            return tuple((m.extra or {})[PATH_KEYS_MARK])
    return ()


def resolve_path(value: str, base: Path) -> str:
    """`value` against `base` (the config file's folder), unless it is empty, absolute,
    a URL or a device index."""
    if not value or "://" in value or value.isdigit():
        return value
    path = Path(os.path.expanduser(value))
    return str(path if path.is_absolute() else (base / path).resolve())


def resolve_paths(cfg: S, base: Path, resolved: list[tuple[str, str]] | None = None) -> S:
    """`cfg` with every `ConfigPath` field, at any depth (nested tables, arrays of
    tables, tagged unions), resolved against `base`; each (as written, resolved) pair
    that changed is appended to `resolved` when given."""
    changes: dict[str, Any] = {}
    for field in msgspec.structs.fields(type(cfg)):
        value = getattr(cfg, field.name)
        if isinstance(value, str) and _is_path(field.type):
            new: Any = resolve_path(value, base)
            if resolved is not None and new != value:
                resolved.append((value, new))
        elif isinstance(value, dict) and (keys := _keys(field.type)):
            new = {k: resolve_path(v, base) if k in keys and isinstance(v, str) else v
                   for k, v in value.items()}
            if resolved is not None:
                resolved += [(value[k], new[k]) for k in keys
                             if k in value and new[k] != value[k]]
        elif isinstance(value, msgspec.Struct):
            new = resolve_paths(value, base, resolved)
        elif isinstance(value, tuple) and _is_path_tuple(field.type):
            new = tuple(resolve_path(v, base) for v in value)
            if resolved is not None:
                resolved += [(v, n) for v, n in zip(value, new, strict=True) if v != n]
        elif isinstance(value, tuple) and any(isinstance(v, msgspec.Struct) for v in value):
            new = tuple(resolve_paths(v, base, resolved) if isinstance(v, msgspec.Struct)
                        else v for v in value)
        else:
            continue
        if new != value:
            changes[field.name] = new
    return msgspec.structs.replace(cfg, **changes) if changes else cfg
