"""`aeb keygen`: make the BrakeCommand key of a fusion instance (docs/security.md).

    aeb keygen --instance primary --out /etc/aeb/keys/primary.key
    aeb keygen --instance primary --out keys/primary-2.key     # rotation: a second key

The file (mode 0600) goes to the fusion instance (`fusion.command_key`) and to the brake
(`brake.command_keys`, which may list two keys of the instance while a key is rotated).

Exit codes: 0 written, 2 when the file exists (--force replaces it), the instance is not
a valid name, or the file cannot be written.
"""

import argparse
import re
import sys
from pathlib import Path

from aeb_radar_camera.common.command_auth import new_key, write_key
from aeb_radar_camera.common.log import add_log_level, setup_logging

_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="aeb keygen", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--instance", required=True, help="the fusion instance it signs for")
    parser.add_argument("--out", required=True, type=Path, help="key file to write")
    parser.add_argument("--key-id", help="default: the instance and 8 random hex digits")
    parser.add_argument("--force", action="store_true", help="replace an existing file")
    add_log_level(parser, "WARNING")
    args = parser.parse_args(argv)
    setup_logging("keygen", args.log_level)
    for what, value in (("instance", args.instance), ("key id", args.key_id or "x")):
        if not _NAME.match(value):
            print(f"error: {what} {value!r} must be letters, digits, '_', '-' or '.'",
                  file=sys.stderr)
            return 2
    key = new_key(args.instance, args.key_id)
    try:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        write_key(args.out, key, overwrite=args.force)
    except FileExistsError:
        print(f"error: {args.out} exists (--force replaces it)", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"error: cannot write {args.out}: {exc.strerror}", file=sys.stderr)
        return 2
    print(f"key {key.key_id} for instance {key.instance} in {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
