"""Mutations of valid inputs, for the fuzzers and the harness's garbage floods: byte
level (bit flips, cuts, splices, random bytes) and structure level (a msgpack message or
a configuration with one value replaced by an extreme or a wrong type)."""

import math
import random
from typing import Any

import msgspec

# Values that have broken parsers before: non-finite floats, integers at and past the
# 64-bit limits, wrong types, empty and oversized containers
EXTREMES: tuple[Any, ...] = (
    math.nan, math.inf, -math.inf, 0.0, -0.0, 1e308, -1e308, 5e-324,
    0, -1, 1, 2**31, 2**63 - 1, -(2**63), 2**64 - 1, 2**62,
    "", "x" * 300, "\x00", "../..", None, True, False, [], {}, [1, 2, 3], {"k": 1}, b"\xff",
)


def mutate_bytes(rng: random.Random, data: bytes) -> bytes:
    """One byte-level mutation of `data` (possibly empty, possibly equal by chance)."""
    b = bytearray(data)
    op = rng.randrange(9)
    if op == 0 and b:                       # flip 1..8 bits
        for _ in range(rng.randint(1, 8)):
            i = rng.randrange(len(b))
            b[i] ^= 1 << rng.randrange(8)
    elif op == 1 and b:                     # cut short
        del b[rng.randrange(len(b)):]
    elif op == 2:                           # random bytes appended
        b += rng.randbytes(rng.randint(1, 64))
    elif op == 3 and b:                     # a range overwritten
        i = rng.randrange(len(b))
        n = min(len(b) - i, rng.randint(1, 16))
        b[i:i + n] = rng.randbytes(n)
    elif op == 4 and b:                     # random bytes inserted
        i = rng.randrange(len(b) + 1)
        b[i:i] = rng.randbytes(rng.randint(1, 16))
    elif op == 5 and len(b) > 1:            # a range duplicated (splice)
        i = rng.randrange(len(b))
        j = rng.randrange(i, len(b))
        b[j:j] = b[i:j + 1]
    elif op == 6:                           # all random
        return rng.randbytes(rng.randint(0, max(1, 2 * len(b))))
    elif op == 7 and b:                     # one byte set to an edge value
        b[rng.randrange(len(b))] = rng.choice((0x00, 0x7F, 0x80, 0xFF, 0x0A, 0x24))
    else:                                   # empty
        return b""
    return bytes(b)


def _leaves(obj: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out: list[tuple[Any, ...]] = [path]
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += _leaves(v, (*path, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            out += _leaves(v, (*path, i))
    return out


def _pick(rng: random.Random, tree: Any) -> tuple[Any, Any] | None:
    """A random node of `tree` as (its parent, its key or index); None for the root."""
    path = rng.choice(_leaves(tree))
    if not path:
        return None
    parent = tree
    for p in path[:-1]:
        parent = parent[p]
    return parent, path[-1]


def mutate_tree(rng: random.Random, obj: Any) -> Any:
    """A deep copy of a plain tree (dicts, lists, scalars) with one node replaced by an
    extreme value, deleted, or given an unknown sibling."""
    tree = msgspec.json.decode(msgspec.json.encode(obj))
    picked = _pick(rng, tree)
    if picked is None:
        return rng.choice(EXTREMES)
    parent, last = picked
    op = rng.randrange(10)
    if op == 0 and isinstance(parent, dict):
        del parent[last]
    elif op == 1 and isinstance(parent, dict):
        parent[f"unknown_{rng.randrange(100)}"] = rng.choice(EXTREMES)
    elif op == 2 and isinstance(parent, list):
        parent.append(parent[last])
    else:
        parent[last] = rng.choice(EXTREMES)
    return tree


def mutate_msgpack(rng: random.Random, payload: bytes) -> bytes:
    """A msgpack payload with one value replaced (structure kept), or a byte mutation."""
    if rng.random() < 0.5:
        return mutate_bytes(rng, payload)
    tree = msgspec.msgpack.decode(payload)
    mutated = _mutate_any(rng, tree)
    return msgspec.msgpack.encode(mutated)


def _mutate_any(rng: random.Random, tree: Any) -> Any:
    # msgpack trees may hold bytes and non-finite floats, which JSON cannot carry
    picked = _pick(rng, tree)
    if picked is None:
        return rng.choice(EXTREMES)
    parent, last = picked
    parent[last] = rng.choice(EXTREMES)
    return tree
