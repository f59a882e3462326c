"""The test grid's output: one Markdown table and its JSON (per family and configuration,
each case below), a heat map per family and configuration (ego speed x the family's
parameter point, coloured by impact speed, or by false activations for a no-threat
family) as PNG. The cases' timeline plots are drawn by the workers as they run
(tools/grid/pool.py, with `aeb demo`'s plot).

Raises OSError when a file cannot be written.
"""

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from aeb_radar_camera.tools.grid.score import CaseScore, FamilyScore, SensorFloor, family_scores
from aeb_radar_camera.tools.sim.scenario import ScenarioKind

HEATMAP_DPI = 80
MAX_IMPACT_KPH = 60.0        # the colour scale's top: the grid's highest ego speed


@dataclass
class GridRun:
    """What a grid run reports: its cases' scores, each configuration's file and floor,
    the command, how long it took and where."""

    cases: list[CaseScore]
    configs: dict[str, str]                  # name -> fusion config file
    floors: dict[str, SensorFloor]
    candidate: str | None
    seeds: list[int]
    wall_s: float
    workers: int
    machine: str
    command: str
    families: dict[str, str] = field(default_factory=dict)   # name -> description
    interrupted: bool = False


def param_label(params: dict[str, Any]) -> str:
    return ", ".join(f"{k}={_fmt_value(v)}" for k, v in params.items()) or "-"


def _fmt_value(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _num(x: float | None, digits: int = 1, unit: str = "") -> str:
    return "-" if x is None else f"{x:.{digits}f}{unit}"


def _ms(x: float | None) -> str:
    return "-" if x is None else f"{x * 1000:.0f}"


# -- the heat maps ------------------------------------------------------------------------

def heatmap(family: str, cases: Sequence[CaseScore], path: Path) -> Path:
    """One family under one configuration: a cell per (parameter point, ego speed),
    coloured by the mean impact speed over its seeds (0: avoided) for a threat family,
    by the share of its seeds with a false activation for a no-threat one; a cell's text
    says how many of its seeds passed. Returns the path."""
    speeds = sorted({c.speed_kph for c in cases})
    points: list[str] = []
    for c in cases:
        label = param_label(c.params)
        if label not in points:
            points.append(label)
    threat = cases[0].kind == ScenarioKind.THREAT.value
    value = np.full((len(points), len(speeds)), np.nan)
    text = [["" for _ in speeds] for _ in points]
    for i, label in enumerate(points):
        for j, v in enumerate(speeds):
            cell = [c for c in cases if c.speed_kph == v and param_label(c.params) == label]
            if not cell:
                continue
            ran = [c for c in cell if not c.error]
            if not ran:
                text[i][j] = "err"
                continue
            passed = sum(c.passed for c in ran)
            if threat:
                impacts = [(c.impact_speed_kph or 0.0) if c.collision else 0.0 for c in ran]
                value[i, j] = float(np.mean(impacts))
                text[i][j] = ("ok" if passed == len(ran) else f"{value[i, j]:.0f}")
            else:
                value[i, j] = sum(bool(c.false_activations) for c in ran) / len(ran)
                text[i][j] = "ok" if passed == len(ran) else "FA"
            if len(cell) > 1:
                text[i][j] += f"\n{passed}/{len(cell)}"
    fig_w = 2.2 + 0.7 * len(speeds) + 0.06 * max(len(p) for p in points)
    fig, ax = plt.subplots(figsize=(fig_w, 1.3 + 0.32 * len(points)))
    cmap = plt.get_cmap("RdYlGn_r").with_extremes(bad="#dddddd")
    top = MAX_IMPACT_KPH if threat else 1.0
    image = ax.imshow(np.ma.masked_invalid(value), cmap=cmap, vmin=0.0, vmax=top,
                      aspect="auto")
    for i in range(len(points)):
        for j in range(len(speeds)):
            ax.text(j, i, text[i][j], ha="center", va="center", fontsize=7)
    ax.set_xticks(range(len(speeds)), [f"{v:g}" for v in speeds], fontsize=8)
    ax.set_yticks(range(len(points)), points, fontsize=7)
    ax.set_xlabel("ego speed (km/h)", fontsize=8)
    bar = fig.colorbar(image, ax=ax, fraction=0.05, pad=0.02)
    bar.ax.tick_params(labelsize=7)
    bar.set_label("impact speed (km/h, 0: avoided)" if threat
                  else "share with a false activation", fontsize=7)
    fig.suptitle(f"{family} [{cases[0].config}]", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=HEATMAP_DPI)
    plt.close(fig)
    return path


def heatmaps(run: GridRun, out: Path) -> list[Path]:
    """Every family's heat map per configuration, under out/<config>/heatmaps/."""
    by: dict[tuple[str, str], list[CaseScore]] = {}
    for c in run.cases:
        by.setdefault((c.config, c.family), []).append(c)
    return [heatmap(family, cases, out / config / "heatmaps" / f"{family}.png")
            for (config, family), cases in by.items()]


# -- the table -------------------------------------------------------------------------------

def _family_cells(f: FamilyScore | None) -> list[str]:
    if f is None:
        return ["-"] * 6
    if f.kind == ScenarioKind.THREAT.value:
        result = f"{f.avoided}/{f.cases}"
        impact = (f"{_num(f.mean_impact_kph, 0)} / {_num(f.max_impact_kph, 0)}"
                  if f.impact_speeds_kph else "-")
        react = (f"{_ms(_median(f.reaction_brake_s))} / {_ms(_median(f.reaction_half_s))}")
        lag = _ms(_median(f.lag_brake_s))
    else:
        result = f"{f.passed}/{f.cases}"
        impact = f"{f.false_activation_cases} ({f.false_activations})"
        react, lag = "", ""
    if f.errors:
        result += f" ({f.errors} err)"
    return [result, impact, f"{f.score_pct:.0f}", react, lag,
            str(f.shadow_cases) if f.shadow_cases else ""]


def _median(values: Sequence[float]) -> float | None:
    return float(np.median(values)) if values else None


def family_table(run: GridRun) -> str:
    """The Markdown family table: a row per family, a column group per configuration."""
    fams = family_scores(run.cases)
    by = {(f.family, f.config): f for f in fams}
    names = list(dict.fromkeys(f.family for f in fams))
    configs = list(run.configs)
    head = ["family", "kind"]
    for name in configs:
        floor = run.floors[name]
        head += [f"{name}: avoided (threat) / passed (no threat)",
                 "impact km/h mean / max; false-activation cases (activations)",
                 "points %",
                 f"reaction ms: in reach -> BRAKE / 50 %, median (floor {_ms(floor.brake_s)}"
                 f" / {_ms(floor.half_s)})",
                 f"lag ms: BRAKE due -> BRAKE, median (floor {_ms(floor.brake_s)})"]
        if run.candidate:
            head.append(f"cases where {run.candidate} decided differently")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for family in names:
        kind = next(f.kind for f in fams if f.family == family)
        row = [family, "threat" if kind == ScenarioKind.THREAT.value else "no threat"]
        for name in configs:
            cells = _family_cells(by.get((family, name)))
            row += cells if run.candidate else cells[:5]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def totals(run: GridRun) -> list[str]:
    """A line per configuration: its points over every threat and every no-threat case."""
    out = []
    for name in run.configs:
        mine = [c for c in run.cases if c.config == name]
        threat = [c for c in mine if c.kind == ScenarioKind.THREAT.value]
        quiet = [c for c in mine if c.kind != ScenarioKind.THREAT.value]
        avoided = sum(c.avoided for c in threat)
        fa = sum(bool(c.false_activations) for c in quiet)
        out.append(
            f"- **{name}** ({run.configs[name]}): threat cases avoided {avoided}/{len(threat)}, "
            f"points {_pct(threat)}; no-threat cases with a false activation "
            f"{fa}/{len(quiet)}, points {_pct(quiet)}; errors "
            f"{sum(bool(c.error) for c in mine)}")
    return out


def _pct(cases: Sequence[CaseScore]) -> str:
    return f"{100 * sum(c.points for c in cases) / len(cases):.0f} %" if cases else "-"


def case_table(cases: Sequence[CaseScore]) -> str:
    head = ["case", "config", "outcome", "1st WARNING s (TTC s)", "1st BRAKE s (TTC s)",
            "in reach s", "reaction ms BRAKE / 50 %", "lag ms", "points"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for c in cases:
        lines.append("| " + " | ".join([
            c.name, c.config, c.error or (f"{c.outcome}: {c.why}" if c.why else c.outcome),
            f"{_num(c.first_warning_t_s, 2)} ({_num(c.first_warning_ttc_s, 2)})",
            f"{_num(c.first_brake_t_s, 2)} ({_num(c.first_brake_ttc_s, 2)})",
            _num(c.in_reach_t_s, 2), f"{_ms(c.reaction_brake_s)} / {_ms(c.reaction_half_s)}",
            _ms(c.lag_brake_s), f"{c.points:.2f}"]) + " |")
    return "\n".join(lines)


def shadow_table(cases: Sequence[CaseScore]) -> str:
    rows = [c for c in cases if c.shadow is not None and c.shadow.differing]
    if not rows:
        return "The candidate decided as the followed instance in every cycle of every case."
    head = ["case", "config", "cycles differing", "first at s (followed -> candidate)",
            "1st BRAKE followed / candidate s"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for c in rows:
        s = c.shadow
        assert s is not None
        lines.append(f"| {c.name} | {c.config} | {s.differing}/{s.cycles} | "
                     f"{_num(s.first_t_s, 2)} ({s.first}) | {_num(s.primary_brake_t_s, 2)} / "
                     f"{_num(s.candidate_brake_t_s, 2)} |")
    return "\n".join(lines)


def markdown(run: GridRun) -> str:
    seeds = (f"{len(run.seeds)} seed{'s' if len(run.seeds) > 1 else ''}: "
             f"{_seed_text(run.seeds)}")
    lines = [
        "# aeb grid", "",
        "A SIMULATION: the services' cores in lockstep with the simulator "
        "(tools/grid/lockstep.py).", "",
        f"`{run.command}`: {len(run.cases)} runs ({seeds}) in {run.wall_s:.0f} s with "
        f"{run.workers} worker{'s' if run.workers > 1 else ''} on {run.machine}."
        + (" INTERRUPTED: the cases finished by then." if run.interrupted else ""), "",
        *totals(run), "",
        "Sensor floor per configuration: "
        + "; ".join(f"{n}: {f.describe()}" for n, f in run.floors.items()) + ".", "",
        family_table(run), ""]
    if run.candidate:
        lines += [f"## Where {run.candidate} decided differently (shadow mode)", "",
                  shadow_table(run.cases), ""]
    lines += ["## Cases", "", case_table(run.cases), ""]
    return "\n".join(lines)


def summary(run: GridRun) -> str:
    """For the terminal: the totals and a line per family and configuration."""
    lines = ["", *totals(run), ""]
    for f in family_scores(run.cases):
        if f.kind == ScenarioKind.THREAT.value:
            what = (f"avoided {f.avoided}/{f.cases}, impact mean/max "
                    f"{_num(f.mean_impact_kph, 0)}/{_num(f.max_impact_kph, 0)} km/h, "
                    f"lag {_ms(_median(f.lag_brake_s))} ms")
        else:
            what = (f"passed {f.passed}/{f.cases}, false activations in "
                    f"{f.false_activation_cases}")
        err = f", {f.errors} errors" if f.errors else ""
        diff = f", candidate differs in {f.shadow_cases}" if f.shadow_cases else ""
        lines.append(f"{f.family:<18} {f.config:<14} {f.score_pct:5.0f} %  {what}{err}{diff}")
    return "\n".join(lines)


def _seed_text(seeds: Sequence[int]) -> str:
    if len(seeds) > 3 and seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f"{seeds[0]}-{seeds[-1]}"
    return ", ".join(str(s) for s in seeds)


def as_json(run: GridRun) -> dict[str, Any]:
    def clean(x: Any) -> Any:
        if isinstance(x, float) and not math.isfinite(x):
            return None
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, list):
            return [clean(v) for v in x]
        return x

    return clean({
        "command": run.command, "machine": run.machine, "workers": run.workers,
        "wall_s": round(run.wall_s, 1), "seeds": run.seeds, "configs": run.configs,
        "candidate": run.candidate, "interrupted": run.interrupted,
        "floors": {n: asdict(f) | {"brake_s": f.brake_s, "half_s": f.half_s}
                   for n, f in run.floors.items()},
        "families": [f.as_dict() for f in family_scores(run.cases)],
        "cases": [asdict(c) for c in run.cases]})


def write(run: GridRun, out: Path) -> tuple[Path, Path, list[Path]]:
    """grid.md, grid.json and the heat maps under `out`."""
    out.mkdir(parents=True, exist_ok=True)
    md, js = out / "grid.md", out / "grid.json"
    md.write_text(markdown(run), encoding="utf-8")
    js.write_text(json.dumps(as_json(run), indent=1), encoding="utf-8")
    return md, js, heatmaps(run, out)
