"""`aeb <command> ...`: one entry point; each command lives in its own module, named in
the command table (tools/commands.py).

Commands are imported lazily so that `aeb brake` never pays for OpenCV.
"""

import ast
import importlib
import importlib.metadata
import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType

from aeb_radar_camera.tools.commands import COMMAND_EXTRA, COMMANDS, OPTIONAL_MODULES

DISTRIBUTION = "aeb-radar-camera"
# The checkout that holds this file, when it is run from one (an editable install): the
# benchmarks live there, beside the package's folders, and are not installed.
CHECKOUT = Path(__file__).resolve().parents[1]


def version() -> str:
    try:
        return importlib.metadata.version(DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError:   # run from a checkout, not installed
        return "unknown (not installed)"


def usage() -> str:
    lines = ["usage: aeb <command> [options]    (aeb --version; aeb <command> --help)", "",
             "commands:"]
    lines += [f"  {name:<13} {doc}" for name, (_, doc) in COMMANDS.items()]
    return "\n".join(lines)


def module_doc(module: str) -> str:
    """A module's docstring read from its source, without importing it."""
    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None:
        return ""
    tree = ast.parse(Path(spec.origin).read_text(encoding="utf-8"))
    return (ast.get_docstring(tree) or "").strip()


def import_command(module: str) -> ModuleType:
    """The command's module. The benchmarks (`aeb bench`) are found in the checkout this
    package is run from. Raises ModuleNotFoundError as import_module does."""
    in_checkout = (CHECKOUT / "benchmarks" / "__init__.py").is_file()
    if module.split(".")[0] == "benchmarks" and in_checkout and str(CHECKOUT) not in sys.path:
        sys.path.append(str(CHECKOUT))
    return importlib.import_module(module)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if not args or args[0] in ("-h", "--help"):
        print(usage())
        return 0
    if args[0] in ("-V", "--version"):
        print(f"aeb {version()} ({DISTRIBUTION}, Python {sys.version.split()[0]})")
        return 0
    name, rest = args[0], args[1:]
    if name not in COMMANDS:
        print(f"error: unknown command {name!r}\n\n{usage()}", file=sys.stderr)
        return 2
    try:
        module = import_command(COMMANDS[name][0])
    except ModuleNotFoundError as exc:
        if exc.name == "benchmarks":
            print(f"error: aeb {name} runs the benchmarks of a checkout of the repository, "
                  "which are not installed: from a clone, python -m benchmarks",
                  file=sys.stderr)
            return 2
        missing = (exc.name or "").split(".")[0]
        if missing not in OPTIONAL_MODULES:
            raise
        extra = COMMAND_EXTRA.get(name, OPTIONAL_MODULES[missing])
        install = (f"aeb {name} needs the Python package {exc.name!r}, which is not "
                   f"installed: pip install 'aeb-radar-camera[{extra}]'")
        if "-h" in rest or "--help" in rest:
            # A command whose module cannot be imported without its extra: its own
            # description, read from the source, and what to install for the options.
            print(f"aeb {name}: {COMMANDS[name][1]}\n\n{module_doc(COMMANDS[name][0])}\n"
                  f"(its options are listed once it can run: {install})")
            return 0
        print(f"error: {install}", file=sys.stderr)
        return 2
    try:
        result = module.main(rest)
    except BrokenPipeError:   # the reader went away (`aeb echo KEY | head`): not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    return int(result or 0)


if __name__ == "__main__":
    sys.exit(main())
