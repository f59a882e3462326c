"""Does the shipped camera check miss what the paper's gate brakes for? Closed loop, in
lockstep, on generated HELD-OUT cases (tools/sim/families.py, seeds of SPLITS['heldout']:
nothing here was used to fit anything), the shipped deploy/fusion.toml against
deploy/fusion-paper.toml. A SIMULATION.

    python -m aeb_radar_camera.tools.grid.recall_cases --out out/recall       # >= 200 cases
    python -m aeb_radar_camera.tools.grid.recall_cases --issue-rows --runs 10  # issue 25's rows
    python -m aeb_radar_camera.tools.grid.recall_cases --quick                 # a few (tests)

The cases: threat families at 10-30 km/h with every obstacle kind the simulator has
(obstacle_standing: boxes 0.4-1.5 m, pedestrians, a bicycle, a car, facing or side-on;
obstacle_crossing: each kind from the near or far side; cyclist_from_kerb; CPNA-25; day and dusk,
CPNA-25 by night), false-target families at several ranges and speeds (plate, overhead
sign, ghost). Per family: threats avoided and the mean impact speed of those hit;
false-target cases with a brake activation. `regressions`: the cases the paper avoids and
the default does not (the check is meant to have none). Writes recall_cases.json,
recall_cases.md (the tables) and one PNG per family under --out; prints a line per case
as it finishes.

`--issue-rows`: the four scenarios of issue 25 (the cyclist crossing from the kerb at 20 km/h,
a bicycle standing across the lane at 25 km/h, a 0.4 m box at 20 km/h, the shipped
`bicycle_crossing_20kph`), `--runs` times each with the default config: the first three
on held-out seeds, the shipped scenario on loop seeds 0.. (its world is fixed).
"""

import argparse
import json
import sys
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aeb_radar_camera.common.resources import DEPLOY
from aeb_radar_camera.tools.grid.pool import Case, Outcome, print_progress, run_cases
from aeb_radar_camera.tools.sim.families import FAMILIES, SPLITS
from aeb_radar_camera.tools.sim.families import Case as FamilyCase
from aeb_radar_camera.tools.sim.scenario import Scenario, ScenarioKind, find_scenario, load_scenario

DEFAULT = DEPLOY / "fusion.toml"
PAPER = DEPLOY / "fusion-paper.toml"
CONFIGS = {"default": DEFAULT, "paper": PAPER}
HELDOUT = list(SPLITS["heldout"])
THREAT_SPEEDS = (10.0, 20.0, 30.0)
FALSE_SPEEDS = (10.0, 30.0, 50.0)
# family -> (speeds, seeds per grid point): 201 cases
PLAN: dict[str, tuple[tuple[float, ...], int]] = {
    "obstacle_standing": (THREAT_SPEEDS, 1),
    "obstacle_crossing": (THREAT_SPEEDS, 1),
    "cyclist_from_kerb": (THREAT_SPEEDS, 5),
    "CPNA-25": (THREAT_SPEEDS, 1),
    "plate": (FALSE_SPEEDS, 2),
    "overhead_sign": (FALSE_SPEEDS, 1),
    "ghost": (FALSE_SPEEDS, 2),
}
QUICK_PLAN: dict[str, tuple[tuple[float, ...], int]] = {
    "obstacle_standing": ((20.0,), 1), "ghost": ((30.0,), 1)}


def generated(plan: dict[str, tuple[tuple[float, ...], int]], quick: bool = False
              ) -> list[FamilyCase]:
    """The plan's cases; held-out seeds, a distinct one per case within a family."""
    out: list[FamilyCase] = []
    for name, (speeds, per_point) in plan.items():
        fam = FAMILIES[name]
        points = [(v, p) for v, p in fam.grid() if v in speeds]
        if quick:
            points = points[:1]
        seeds = iter(HELDOUT)
        for v, p in points:
            out += [FamilyCase(name, v, p, next(seeds)) for _ in range(per_point)]
    return out


@dataclass
class Row:
    """One case under one config."""

    family: str
    case: str
    speed_kph: float
    config: str
    threat: bool
    avoided: bool
    impact_kph: float | None
    activations: int
    warnings: int
    error: str = ""


def _row(family: str, config: str, o: Outcome) -> Row:
    sc = o.case.scenario
    threat = sc.kind is ScenarioKind.THREAT
    if o.result is None:
        return Row(family, sc.name, sc.ego.speed_kph, config, threat, False, None, 0, 0,
                   o.error)
    v = o.result.verdict
    return Row(family, sc.name, sc.ego.speed_kph, config, threat, not v.collision,
               v.impact_speed_kph, v.brake_activations, v.warnings)


def run_all(scenarios: Sequence[tuple[str, Scenario]], configs: dict[str, Path],
            workers: int, loop_seeds: Sequence[int] = (0,)) -> list[Row]:
    cases, meta = [], []
    for family, sc in scenarios:
        for label, path in configs.items():
            for seed in loop_seeds:
                cases.append(Case(sc, path, loop_seed=seed, name=f"{sc.name} [{label}]"))
                meta.append((family, label))
    outcomes = run_cases(cases, workers, print_progress(sys.stdout))
    return [_row(f, c, o) for (f, c), o in zip(meta, outcomes, strict=True)]


def summarise(rows: list[Row]) -> dict[str, Any]:
    """Per family and config: cases, avoided (threats), mean impact speed of the hits,
    cases with an activation (false targets); the regressions and every miss."""
    table: dict[str, dict[str, dict[str, Any]]] = defaultdict(dict)
    groups: dict[tuple[str, str], list[Row]] = defaultdict(list)
    for r in rows:
        groups[(r.family, r.config)].append(r)
    for (family, config), rs in sorted(groups.items()):
        hits = [r.impact_kph for r in rs if r.threat and not r.avoided and r.impact_kph]
        table[family][config] = {
            "cases": len(rs), "threat": rs[0].threat,
            "avoided": sum(r.avoided for r in rs if r.threat),
            "mean_impact_kph": sum(hits) / len(hits) if hits else None,
            "with_activation": sum(r.activations > 0 for r in rs if not r.threat),
            "errors": sum(bool(r.error) for r in rs)}
    by_case: dict[str, dict[str, Row]] = defaultdict(dict)
    for r in rows:
        by_case[r.case][r.config] = r
    regressions = sorted(c for c, rr in by_case.items() if "paper" in rr and "default" in rr
                         and rr["paper"].threat and rr["paper"].avoided
                         and not rr["default"].avoided)
    misses = {cfg: sorted(r.case for r in rows if r.config == cfg and r.threat
                          and not r.avoided) for cfg in {r.config for r in rows}}
    false_act = {cfg: sorted(r.case for r in rows if r.config == cfg and not r.threat
                             and r.activations > 0) for cfg in {r.config for r in rows}}
    return {"families": table, "regressions": regressions, "misses": misses,
            "false_activations": false_act}


def markdown(summary: dict[str, Any], configs: Sequence[str]) -> str:
    head = "| family | cases | " + " | ".join(
        f"{c}: avoided / with activation | {c}: mean impact (km/h)" for c in configs) + " |"
    lines = [head, "|" + "---|" * (2 + 2 * len(configs))]
    for family, per in summary["families"].items():
        first = next(iter(per.values()))
        cells = []
        for c in configs:
            s = per.get(c)
            if s is None:
                cells += ["-", "-"]
            elif s["threat"]:
                mean = s["mean_impact_kph"]
                cells += [f"{s['avoided']}/{s['cases']} avoided",
                          f"{mean:.1f}" if mean is not None else "-"]
            else:
                cells += [f"{s['with_activation']}/{s['cases']} activated", "-"]
        kind = "threat" if first["threat"] else "false target"
        lines.append(f"| {family} ({kind}) | {first['cases']} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot_family(family: str, rows: list[Row], configs: Sequence[str], path: Path) -> None:
    """Per ego speed: share of threats avoided (or of false-target cases with a brake
    activation) for each config."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    speeds = sorted({r.speed_kph for r in rows})
    threat = rows[0].threat
    fig, ax = plt.subplots(figsize=(6, 3.4))
    width = 0.8 / len(configs)
    for k, cfg in enumerate(configs):
        shares = []
        for v in speeds:
            rs = [r for r in rows if r.config == cfg and r.speed_kph == v]
            good = sum(r.avoided for r in rs) if threat else sum(r.activations > 0 for r in rs)
            shares.append(100.0 * good / len(rs) if rs else 0.0)
        ax.bar([i + k * width for i in range(len(speeds))], shares, width,
               label=f"{cfg} ({CONFIGS.get(cfg, Path(cfg)).name})")
    ax.set_xticks([i + width * (len(configs) - 1) / 2 for i in range(len(speeds))])
    ax.set_xticklabels([f"{v:g} km/h" for v in speeds])
    ax.set_ylim(0, 105)
    ax.set_ylabel("threats avoided (%)" if threat else "cases with a brake activation (%)")
    n = len({r.case for r in rows})
    ax.set_title(f"{family}: {n} held-out cases (SIMULATION, lockstep)", fontsize=10)
    ax.legend(fontsize=8, loc="lower right" if threat else "upper right")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def issue_rows(runs: int) -> list[tuple[str, Scenario, int]]:
    """(row, scenario, loop seed) for issue 25's four rows, `runs` each."""
    seeds = HELDOUT[:runs]
    standing = (("object", "bicycle"), ("size_m", 1.8), ("pose", "side-on"), ("light", "day"))
    box = (("object", "box"), ("size_m", 0.4), ("pose", "facing"), ("light", "day"))
    out: list[tuple[str, Scenario, int]] = []
    for s in seeds:
        out.append(("cyclist crossing from the kerb 20 km/h",
                    FamilyCase("cyclist_from_kerb", 20.0, (), s).scenario(), 0))
        out.append(("bicycle standing across the lane 25 km/h",
                    FamilyCase("obstacle_standing", 25.0, standing, s).scenario(), 0))
        out.append(("0.4 m box 20 km/h", FamilyCase("obstacle_standing", 20.0, box, s)
                    .scenario(), 0))
    shipped = load_scenario(find_scenario("bicycle_crossing_20kph"))
    out += [("shipped bicycle_crossing_20kph", shipped, k) for k in range(runs)]
    return out


def run_issue_rows(runs: int, workers: int) -> dict[str, Any]:
    plan = issue_rows(runs)
    cases = [Case(sc, DEFAULT, loop_seed=seed, name=f"{row}: {sc.name} loop {seed}")
             for row, sc, seed in plan]
    outcomes = run_cases(cases, workers, print_progress(sys.stdout))
    result: dict[str, dict[str, Any]] = {}
    for (row, sc, seed), o in zip(plan, outcomes, strict=True):
        r = result.setdefault(row, {"runs": 0, "avoided": 0, "hits": []})
        r["runs"] += 1
        if o.result is not None and not o.result.verdict.collision:
            r["avoided"] += 1
        else:
            r["hits"].append({"case": sc.name, "loop_seed": seed, "error": o.error,
                              "impact_kph": o.result.verdict.impact_speed_kph
                              if o.result is not None else None})
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m aeb_radar_camera.tools.grid.recall_cases",
                                     description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="out/recall", help="where the results go")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--quick", action="store_true", help="a few cases")
    parser.add_argument("--issue-rows", action="store_true",
                        help="issue 25's four scenarios, --runs times each, default config")
    parser.add_argument("--runs", type=int, default=10)
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.issue_rows:
        result = run_issue_rows(args.runs, args.workers)
        (out / "issue_rows.json").write_text(json.dumps(result, indent=2))
        for row, r in result.items():
            print(f"{row}: avoided {r['avoided']}/{r['runs']}")
        return 0 if all(r["avoided"] == r["runs"] for r in result.values()) else 1
    cases = generated(QUICK_PLAN if args.quick else PLAN, args.quick)
    print(f"{len(cases)} held-out cases x {len(CONFIGS)} configs, {args.workers} workers",
          flush=True)
    rows = run_all([(c.family, c.scenario()) for c in cases], CONFIGS, args.workers)
    summary = summarise(rows)
    configs = list(CONFIGS)
    table = markdown(summary, configs)
    (out / "recall_cases.json").write_text(json.dumps(
        {"summary": summary, "rows": [r.__dict__ for r in rows],
         "seeds": "heldout", "configs": {k: str(v) for k, v in CONFIGS.items()}}, indent=1))
    (out / "recall_cases.md").write_text(table + "\n")
    by_family: dict[str, list[Row]] = defaultdict(list)
    for r in rows:
        by_family[r.family].append(r)
    for family, rs in by_family.items():
        plot_family(family, rs, configs, out / f"recall_{family}.png")
    print(table)
    print(f"regressions (paper avoids, default does not): {len(summary['regressions'])}")
    for c in summary["regressions"]:
        print(f"  {c}")
    for cfg, missed in summary["misses"].items():
        print(f"{cfg}: {len(missed)} threat(s) hit" + "".join(f"\n  {c}" for c in missed))
    for cfg, act in summary["false_activations"].items():
        print(f"{cfg}: {len(act)} false-target case(s) with an activation")
    return 0 if not summary["regressions"] else 1


if __name__ == "__main__":
    sys.exit(main())
