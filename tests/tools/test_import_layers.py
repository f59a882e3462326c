"""The tools' imports run one way: every unit of tools/ (a package, or a module at its top
level) imports only units of lower layers (`LAYERS`), no imports go round in a circle
(between units, or between modules inside one), and nothing in tools/ imports
benchmarks/ (the benchmarks may import the tools). Imports inside functions count.

`python -m tests.tools.test_import_layers` prints the graph between units.
"""

import ast
import sys
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

TOOLS = Path(__file__).resolve().parents[2] / "tools"
PACKAGE = "aeb_radar_camera"       # tools/ is installed as aeb_radar_camera.tools

# Bottom to top.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("arrivals", "bus", "commands", "machine", "messages"),   # import nothing of tools/
    ("keys",),                                      # the registry plus the simulator's key
    # commands on the bus and on files
    ("calib", "can_export", "init", "keygen", "monitor", "schemas", "topics"),
    ("launch",),                                    # aeb up: process tables, supervisor
    ("sim",),                                       # the simulator and its closed loop
    ("recording",),                                 # MCAP, replay, rerun, evidence
    ("ab", "eval", "faults", "foxglove", "grid"),   # what stands on recordings and the sim
    ("cli", "demo"),                                # top-level commands
)
LAYER_OF = {unit: i for i, layer in enumerate(LAYERS) for unit in layer}


@dataclass(frozen=True)
class Import:
    module: str          # the importing module, e.g. aeb_radar_camera.tools.recording.record
    line: int
    target: str          # the imported module, or the package a name was imported from


def module_name(path: Path, root: Path) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_of(module: str, source: str, is_package: bool,
               known: Iterable[str] = ()) -> list[Import]:
    """Every import statement of `source`, at any depth (inside functions too), as
    absolute module names. `from a import b` is module a.b when `known` has it, else a
    (b is a name in a)."""
    known = set(known)
    package = module if is_package else module.rpartition(".")[0]
    found: dict[Import, None] = {}       # in order, once each
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found |= {Import(module, node.lineno, a.name): None for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:       # relative: from the package, one level up per dot
                parts = package.split(".")
                base = ".".join([*parts[:len(parts) - node.level + 1], *([base] if base else [])])
            for alias in node.names:
                full = f"{base}.{alias.name}"
                found[Import(module, node.lineno, full if full in known else base)] = None
    return list(found)


def tools_imports(root: Path = TOOLS) -> list[Import]:
    paths = {f"{PACKAGE}.{module_name(p, root.parent)}": p for p in sorted(root.rglob("*.py"))}
    found = []
    for name, path in paths.items():
        found += imports_of(name, path.read_text(encoding="utf-8"),
                            path.name == "__init__.py", paths)
    return found


def unit(module: str) -> str | None:
    """aeb_radar_camera.tools.recording.record -> recording; aeb_radar_camera.tools.demo ->
    demo; None outside tools/."""
    parts = module.split(".")
    return parts[2] if parts[:2] == [PACKAGE, "tools"] and len(parts) > 2 else None


def units(root: Path = TOOLS) -> set[str]:
    return {p.stem for p in root.glob("*.py") if p.stem != "__init__"} | {
        p.name for p in root.iterdir() if (p / "__init__.py").is_file()}


def unit_graph(found: list[Import]) -> dict[str, dict[str, list[Import]]]:
    """importing unit -> imported unit -> the imports that make the edge."""
    graph: dict[str, dict[str, list[Import]]] = defaultdict(lambda: defaultdict(list))
    for imp in found:
        src, dst = unit(imp.module), unit(imp.target)
        if src is not None and dst is not None and src != dst:
            graph[src][dst].append(imp)
    return graph


def circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one member (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def where(imports: list[Import]) -> str:
    return ", ".join(f"{i.module}:{i.line} imports {i.target}" for i in imports)


def test_every_unit_of_tools_has_a_layer():
    found = units()
    assert not found - set(LAYER_OF), \
        f"units without a layer in LAYERS: {sorted(found - set(LAYER_OF))}"
    assert not set(LAYER_OF) - found, \
        f"LAYERS names units that do not exist: {sorted(set(LAYER_OF) - found)}"


def test_nothing_in_tools_imports_benchmarks():
    upward = [i for i in tools_imports() if i.target.split(".")[0] == "benchmarks"]
    assert not upward, where(upward)


def test_imports_run_down_the_layers():
    wrong = [imp for src, dsts in unit_graph(tools_imports()).items() for dst, imps in dsts.items()
             if LAYER_OF.get(dst, len(LAYERS)) >= LAYER_OF.get(src, -1) for imp in imps]
    assert not wrong, "imports against the layer order (LAYERS): " + where(wrong)


def test_no_circle_between_units():
    graph = unit_graph(tools_imports())
    assert not circles({src: set(dsts) for src, dsts in graph.items()})


def test_no_circle_between_modules():
    found = tools_imports()
    edges: dict[str, set[str]] = defaultdict(set)
    for imp in found:
        if unit(imp.target) is not None and imp.target != imp.module:
            edges[imp.module].add(imp.target)
    assert not circles(edges)


def test_the_reading_sees_every_form_of_import():
    source = ("import aeb_radar_camera.tools.sim.world\n"
              "from aeb_radar_camera.tools.recording import reader\n"
              "from aeb_radar_camera.tools.recording.format import ChannelType\n"
              "from . import state\n"
              "from ..eval.frames import load_gray\n"
              "def later():\n"
              "    from benchmarks.figures import Figure\n")
    known = {"aeb_radar_camera.tools.recording.reader", "aeb_radar_camera.tools.monitor.state"}
    got = {(i.line, i.target) for i in imports_of("aeb_radar_camera.tools.monitor.main", source,
                                                  False, known)}
    assert got == {(1, "aeb_radar_camera.tools.sim.world"),
                   (2, "aeb_radar_camera.tools.recording.reader"),
                   (3, "aeb_radar_camera.tools.recording.format"),
                   (4, "aeb_radar_camera.tools.monitor.state"),
                   (5, "aeb_radar_camera.tools.eval.frames"), (7, "benchmarks.figures")}
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def main() -> int:
    graph = unit_graph(tools_imports())
    for i, layer in enumerate(LAYERS):
        print(f"layer {i}:")
        for src in layer:
            dsts = ", ".join(f"{d} ({LAYER_OF.get(d, '?')})" for d in sorted(graph.get(src, {})))
            print(f"  {src} -> {dsts or '(nothing of tools/)'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
