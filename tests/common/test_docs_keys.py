"""docs/architecture.md against the code it describes: the key table ("Processes and
keys") lists exactly the keys of the registry (common/keys.py) and of the tools' table
(tools/keys.py: the simulator's `sim/world`), each with its message type, and the
common/ table has a row for every module and package of common/ and none for anything
else. A key or module added without its row, or a row left behind, fails here."""

import re
from pathlib import Path

import pytest

import aeb_radar_camera.common as common
from aeb_radar_camera.common.keys import REGISTRY, KeySpec
from aeb_radar_camera.tools.keys import KEYS

ARCHITECTURE = Path(__file__).resolve().parents[2] / "docs" / "architecture.md"
COMMON = Path(common.__file__).resolve().parent
LIVELINESS = "liveliness token"

_CODE = re.compile(r"^`([^`]+)`$")


def section_table(text: str, heading: str) -> list[list[str]]:
    """The cells of the first Markdown table under `## heading`, header row and rule
    left out, each cell stripped. Raises LookupError when the section or its table is
    missing."""
    lines = text.splitlines()
    try:
        start = lines.index(f"## {heading}")
    except ValueError:
        raise LookupError(f"no section '## {heading}'") from None
    rows: list[list[str]] = []
    for line in lines[start + 1:]:
        if line.startswith("## "):
            break
        if line.startswith("|"):
            rows.append([c.strip() for c in line.strip().strip("|").split("|")])
        elif rows:
            break
    if len(rows) < 2:
        raise LookupError(f"no table under '## {heading}'")
    return rows[2:]


def code(cell: str) -> str:
    """The text of a cell that is one code span; AssertionError naming it otherwise."""
    m = _CODE.match(cell)
    assert m, f"expected one `code` span, got {cell!r}"
    return m.group(1)


def documented_keys(text: str) -> dict[str, tuple[str, str]]:
    """Key table rows by pattern in the registry's spelling (`radar/{sensor}/tracks`):
    (message, publisher). A pattern twice is an AssertionError."""
    keys: dict[str, tuple[str, str]] = {}
    for key, message, publisher in section_table(text, "Processes and keys"):
        pattern = re.sub(r"<(\w+)>", r"{\1}", code(key))
        assert pattern not in keys, f"{key} documented twice"
        keys[pattern] = (message if message == LIVELINESS else code(message), publisher)
    return keys


def message_name(spec: KeySpec) -> str:
    return LIVELINESS if spec.msg_type is None else spec.msg_type.__name__


@pytest.fixture(scope="module")
def text() -> str:
    return ARCHITECTURE.read_text(encoding="utf-8")


def test_every_registered_key_is_documented_with_its_message(text):
    documented = documented_keys(text)
    for spec in KEYS.values():
        assert spec.pattern in documented, (
            f"{spec.name} ({spec.pattern}) has no row in docs/architecture.md's key table")
        assert documented[spec.pattern][0] == message_name(spec), spec.pattern


def test_nothing_is_documented_that_is_not_registered(text):
    registered = {spec.pattern for spec in KEYS.values()}
    stray = sorted(set(documented_keys(text)) - registered)
    assert not stray, f"docs/architecture.md documents keys no KeySpec has: {stray}"


def test_keys_outside_the_product_registry_are_documented_as_the_simulators(text):
    documented = documented_keys(text)
    product = {spec.pattern for spec in REGISTRY.values()}
    tools_only = [spec.pattern for spec in KEYS.values() if spec.pattern not in product]
    assert tools_only, "the tools' key table adds the simulator's ground truth"
    for pattern in tools_only:
        publisher = documented[pattern][1]
        assert "simulator" in publisher and "SIMULATION" in publisher, (pattern, publisher)


def common_modules() -> set[str]:
    """common/'s modules (`keys.py`) and packages (`config/`), its __init__ left out."""
    names = {p.name for p in COMMON.glob("*.py") if p.name != "__init__.py"}
    names |= {f"{p.name}/" for p in COMMON.iterdir()
              if p.is_dir() and (p / "__init__.py").exists()}
    return names


def test_the_common_table_has_a_row_for_every_module_and_no_other(text):
    rows = {code(row[0]) for row in section_table(text, "common/")}
    missing = sorted(common_modules() - rows)
    stray = sorted(rows - common_modules())
    assert not missing, f"common/ modules without a row in docs/architecture.md: {missing}"
    assert not stray, f"docs/architecture.md's common/ table names what is not there: {stray}"


def test_a_missing_row_is_found():
    """The parser reads the rows it is meant to read: a table with a row removed is short
    of exactly that key."""
    full = ARCHITECTURE.read_text(encoding="utf-8")
    row = next(line for line in full.splitlines() if line.startswith("| `can/<bus>/frames`"))
    short = documented_keys(full.replace(row + "\n", ""))
    assert set(documented_keys(full)) - set(short) == {"can/{bus}/frames"}
