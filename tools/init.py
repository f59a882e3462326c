"""`aeb init DIR`: write an editable copy of the shipped deploy/ folder for one vehicle:
the process tables, every service's example config, the calibration example, the Zenoh
and systemd files and the bundled recording. Paths inside the copy are relative to it,
so it works wherever it is; its systemd units are rewritten to run this installation's
`aeb` on the copy's tables.

    aeb init /etc/aeb                       # then edit /etc/aeb/*.toml
    aeb up --check --table /etc/aeb/single-host.toml
    aeb up --table /etc/aeb/single-host.toml

Exit codes: 0 written, 2 when DIR holds files already (--force overwrites them) or
cannot be written.
"""

import argparse
import shutil
import sys
from pathlib import Path

from aeb_radar_camera.common.command_auth import KeyFileError, load_key, new_key, write_key
from aeb_radar_camera.common.log import add_log_level, setup_logging
from aeb_radar_camera.common.resources import DEPLOY

# What the shipped units name, and what they become in a copy
UNIT_AEB = "/opt/aeb/.venv/bin/aeb"
UNIT_CONFIGS = "/etc/aeb"
_SKIP = shutil.ignore_patterns("__pycache__", "*.pyc", "__init__.py")


def installed_aeb() -> str:
    """The `aeb` script of this installation (beside its Python), else the shipped path."""
    script = Path(sys.executable).parent / "aeb"
    return str(script) if script.is_file() else UNIT_AEB


def rewrite_units(folder: Path, configs: Path, aeb: str) -> int:
    """Point the copy's systemd units (and board.env) at `configs` and `aeb`; returns how
    many files changed."""
    changed = 0
    for unit in [*sorted((folder / "systemd").glob("*.service")), folder / "board.env"]:
        text = unit.read_text()
        new = text.replace(UNIT_AEB, aeb).replace(UNIT_CONFIGS, str(configs))
        if new != text:
            unit.write_text(new)
            changed += 1
    return changed


def write_copy(target: Path, force: bool = False) -> list[Path]:
    """Copy deploy/ into `target`; returns the files written. Raises FileExistsError
    when `target` holds files and not `force`, OSError when it cannot be written."""
    if target.exists() and any(target.iterdir()) and not force:
        raise FileExistsError(f"{target} is not empty (--force overwrites the files it "
                              "shares with deploy/)")
    written: list[Path] = []

    def copy(src: str, dst: str) -> None:
        shutil.copy2(src, dst)
        written.append(Path(dst))

    shutil.copytree(DEPLOY, target, ignore=_SKIP, dirs_exist_ok=True, copy_function=copy)
    rewrite_units(target, target.resolve(), installed_aeb())
    replace_example_keys(target / "keys")
    return sorted(written)


def replace_example_keys(folder: Path) -> list[Path]:
    """Every insecure example key in `folder` replaced by a fresh key of the same
    instance (same file name, mode 0600), so that a vehicle's copy never runs on a
    published key. Returns the files replaced. Raises OSError, KeyFileError."""
    replaced: list[Path] = []
    for path in sorted(folder.glob("*.key")):
        key = load_key(path)
        if key.insecure_example:
            write_key(path, new_key(key.instance), overwrite=True)
            replaced.append(path)
    readme = folder / "README.md"
    if replaced:
        readme.write_text("# BrakeCommand keys of this vehicle\n\nMade by `aeb init`; secret: "
                          "readable by the fusion and brake services only.\nRotation: "
                          "docs/security.md.\n")
    return replaced


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="aeb init", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("dir", help="folder to write (created; must be empty)")
    parser.add_argument("--force", action="store_true",
                        help="write into a non-empty folder, overwriting files of the same name")
    add_log_level(parser, "WARNING")
    args = parser.parse_args(argv)
    setup_logging("init", args.log_level)
    target = Path(args.dir)
    try:
        files = write_copy(target, args.force)
    except (FileExistsError, OSError, KeyFileError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {len(files)} files to {target}/ (from {DEPLOY})\n"
          f"  edit the service configs for the vehicle: {target}/radar.toml, camera.toml, "
          "fusion.toml, brake.toml, calibration/\n"
          f"  check:  aeb up --check --table {target}/single-host.toml\n"
          f"  run:    aeb up --table {target}/single-host.toml\n"
          f"  under systemd: {target}/systemd/ (docs/deploy.md)\n"
          f"  command keys: fresh ones in {target}/keys/ (docs/security.md)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
