"""One table, one JSON file and one chart for a list of figures."""

import json
from collections.abc import Sequence
from pathlib import Path
from typing import IO, Any

from benchmarks.figures import Figure

_COLUMNS = ("group", "figure", "value", "unit", "baseline (same run)", "base", "ratio",
            "target", "met")


def _num(v: float | None) -> str:
    if v is None:
        return "-"
    return f"{v:.3g}" if abs(v) < 1000 else f"{v:.0f}"


def rows(figures: Sequence[Figure]) -> list[tuple[str, ...]]:
    out: list[tuple[str, ...]] = []
    for f in figures:
        met = "-" if f.target_met is None else ("yes" if f.target_met else "NO")
        ratio = "-" if f.ratio is None else f"{f.ratio:.2f}x"
        out.append((f.group, f.name, _num(f.value), f.unit, f.baseline or "-",
                    _num(f.baseline_value), ratio, f.target or "-", met))
    return out


def print_table(figures: Sequence[Figure], out: IO[str], max_baseline: int = 38) -> None:
    table = [tuple(c if i != 4 else c[:max_baseline] for i, c in enumerate(r))
             for r in rows(figures)]
    widths = [max(len(h), *(len(r[i]) for r in table)) if table else len(h)
              for i, h in enumerate(_COLUMNS)]
    right = {2, 5, 6}
    def fmt(r: tuple[str, ...]) -> str:
        return "  ".join(c.rjust(w) if i in right else c.ljust(w)
                         for i, (c, w) in enumerate(zip(r, widths, strict=True))).rstrip()
    print(fmt(_COLUMNS), file=out)
    print("  ".join("-" * w for w in widths), file=out)
    for r in table:
        print(fmt(r), file=out)
    notes = [(f.group, f.name, f.note) for f in figures if f.note]
    if notes:
        print("\nnotes:", file=out)
        for g, n, note in notes:
            print(f"  {g} / {n}: {note}", file=out)


def write_json(figures: Sequence[Figure], machine: dict[str, Any], path: Path,
               extra: dict[str, Any] | None = None) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"machine": machine, **(extra or {}),
                                "figures": [f.to_json() for f in figures]}, indent=1))
    return path


def plot(figures: Sequence[Figure], path: Path, title: str = "") -> Path:
    """One panel per (group, unit): each figure's value beside its baseline."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels: dict[tuple[str, str], list[Figure]] = {}
    for f in figures:
        panels.setdefault((f.group, f.unit), []).append(f)
    n = len(panels)
    cols = 2 if n > 1 else 1
    nrows = (n + cols - 1) // cols
    fig, axes = plt.subplots(nrows, cols, figsize=(7 * cols, 0.5 + 0.45 * max(
        len(v) for v in panels.values()) * nrows + 1.2 * nrows), squeeze=False)
    for ax, ((group, unit), figs) in zip(axes.flat, panels.items(), strict=False):
        ys = range(len(figs))
        ax.barh([y + 0.2 for y in ys], [f.value for f in figs], height=0.4,
                color=["tab:red" if f.target_met is False else "tab:blue" for f in figs],
                label="measured")
        base = [f.baseline_value if f.baseline_value is not None else 0.0 for f in figs]
        if any(base):
            ax.barh([y - 0.2 for y in ys], base, height=0.4, color="tab:gray",
                    label="baseline (same run)")
        ax.set_yticks(list(ys), [f.name for f in figs], fontsize=8)
        ax.invert_yaxis()
        ax.set_xlabel(unit)
        ax.set_title(group)
        ax.grid(axis="x", alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
