"""`aeb schemas`: the JSON Schema of every message on the bus (msgspec's), for generic
tools: Foxglove, a bridge, code generators, a validator in another language.

    aeb schemas                      # one JSON document: keys and schemas
    aeb schemas --out schemas/       # aeb.<Type>.json per message, and keys.json

Each schema is named ``aeb.<Type>``, as in every sample's Zenoh encoding
(``application/msgpack;aeb.<Type>``) and in recordings. `keys` maps each key pattern
(under ``aeb/<vehicle>/``) to its message. Schemas evolve by the rule of
docs/architecture.md: fields are only ever added, with a default.

Exit codes: 0 written, 2 when --out cannot be written.
"""

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import msgspec

from aeb_radar_camera.common.log import add_log_level, setup_logging
from aeb_radar_camera.common.messages import SCHEMA_VERSION
from aeb_radar_camera.common.messages.schema import json_schema, schema_name
from aeb_radar_camera.tools.keys import MESSAGE_KEYS, SIM_WORLD


def document() -> dict[str, Any]:
    types: dict[str, type[msgspec.Struct]] = {}
    keys = {}
    for spec in MESSAGE_KEYS:
        assert spec.msg_type is not None
        name = schema_name(spec.msg_type)
        types.setdefault(name, spec.msg_type)
        keys[spec.pattern] = {"schema": name, "rate_hz": spec.rate_hz,
                              "simulation": spec is SIM_WORLD}
    return {"schema_version": SCHEMA_VERSION, "encoding": "msgpack", "keys": keys,
            "schemas": {name: json_schema(t) for name, t in types.items()}}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="aeb schemas", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", help="folder for one file per schema (default: stdout)")
    add_log_level(parser, "WARNING")
    args = parser.parse_args(argv)
    setup_logging("schemas", args.log_level)
    doc = document()
    if not args.out:
        print(json.dumps(doc, indent=1))
        return 0
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        for name, schema in doc["schemas"].items():
            (out / f"{name}.json").write_text(json.dumps(schema, indent=1) + "\n")
        index = {k: v for k, v in doc.items() if k != "schemas"}
        (out / "keys.json").write_text(json.dumps(index, indent=1) + "\n")
    except OSError as exc:
        print(f"error: {out}: {exc.strerror}", file=sys.stderr)
        return 2
    print(f"wrote {len(doc['schemas'])} schemas and keys.json to {out}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
