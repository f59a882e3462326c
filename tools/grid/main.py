"""`aeb grid`: the Euro NCAP-style test grid - the scenario families of tools/sim/families.py
(CCRs, CCRm, CCRb, CPNA, CPFA, CPNC, CPLA, CBNA, CBLA, bends, no-threat situations,
radar false targets) over their ego speeds and parameters, each case played through the
stack's cores in lockstep (tools/grid/lockstep.py), scored (tools/grid/score.py) and
reported: one table (grid.md, grid.json), a heat map per family and configuration, each
case's timeline plot. A SIMULATION.

    aeb grid --quick                                  # one case per family (CI)
    aeb grid                                          # the nominal grid, deploy/fusion.toml
    aeb grid --paper --workers 2                      # ... and deploy/fusion-paper.toml
    aeb grid --ideal --families cyclist_from_kerb     # ... and the IDEAL decision's bound
    aeb grid --families CCRs,CCRb --speeds 40,50,60 --seeds heldout:3
    aeb grid --candidate my-fusion.toml               # a candidate in shadow mode
    aeb grid --list                                   # the families and their grids

--seeds: `nominal` (seed 0, the default), `heldout:N` / `train:N` (the split's first N
randomised variants), `A-B`, numbers; several joined by commas (`0,heldout:3`). Report
figures on `heldout`, never on `train`.

Output under --out (default out/grid): grid.md, grid.json, <config>/heatmaps/<family>.png,
<config>/plots/<family>/<case>.png. Progress goes to stderr, a line per case.

Exit code: 0 when every case ran and was scored (whatever its verdict: the grid is a
measurement), 1 when a case could not run (its error is in the table) or the run was
interrupted (the report covers the cases finished), 2 for bad arguments or a
configuration that does not load.
"""

import argparse
import os
import platform
import shlex
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from aeb_radar_camera.common.log import add_log_level, setup_logging
from aeb_radar_camera.common.resources import DEPLOY

# The grid's machinery (numpy, OpenCV, matplotlib: the demo extra) is imported once the
# arguments are read: `aeb grid --help` works on any install.
if TYPE_CHECKING:
    from aeb_radar_camera.tools.grid.lockstep import LoopConfig
    from aeb_radar_camera.tools.grid.pool import Outcome
    from aeb_radar_camera.tools.grid.score import CaseScore
    from aeb_radar_camera.tools.sim.families import Case as FamilyCase

PAPER_CONFIG = DEPLOY / "fusion-paper.toml"
QUICK_SPEED_KPH = 30.0        # the quick set's speed where a family has it (the paper's)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="aeb grid", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--families", default="all",
                    help="comma-separated families or groups (euro_ncap, bend, road_edge, "
                         "no_threat, false_target, obstacle), or 'all'")
    ap.add_argument("--speeds", default="", help="ego speeds in km/h, comma-separated "
                    "(default: each family's own)")
    ap.add_argument("--seeds", default="nominal", help="nominal | heldout:N | train:N | A-B | "
                    "numbers; several joined by commas (default nominal)")
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1),
                    help="parallel processes (default 2, or 1 on one core)")
    ap.add_argument("--out", type=Path, default=Path("out/grid"))
    ap.add_argument("--quick", action="store_true",
                    help="one case per family (its first point nearest 30 km/h, first seed)")
    ap.add_argument("--config", type=Path, default=DEPLOY / "fusion.toml",
                    help="the fusion configuration the brake follows (default "
                         "deploy/fusion.toml)")
    ap.add_argument("--paper", action="store_true",
                    help="also deploy/fusion-paper.toml, side by side")
    ap.add_argument("--ideal", action="store_true",
                    help="also an IDEAL decision on the same loop (full braking from the "
                         "ground truth's first collision course): what no decision beats")
    ap.add_argument("--candidate", type=Path, default=None, metavar="CONFIG",
                    help="a fusion configuration in shadow mode beside --config: where it "
                         "decided differently")
    ap.add_argument("--no-plots", action="store_true", help="no timeline plot per case")
    ap.add_argument("--list", action="store_true", help="the families and their grids")
    add_log_level(ap, "WARNING")
    return ap.parse_args(argv)


def parse_seeds(text: str) -> list[int]:
    """Seed specs joined by commas, each as tools/sim/families.seeds_of reads it; in
    order, without repeats. Raises ValueError."""
    from aeb_radar_camera.tools.sim.families import seeds_of, split_of

    seeds: list[int] = []
    for part in text.split(","):
        if part.strip():
            seeds += [s for s in seeds_of(part) if s not in seeds]
    if not seeds:
        raise ValueError(f"--seeds {text!r}: no seed")
    for s in seeds:
        split_of(s)
    return seeds


def pick_families(text: str) -> list[str]:
    """Family names from names and group names. Raises ValueError."""
    from aeb_radar_camera.tools.sim.families import FAMILIES

    if text.strip() == "all":
        return list(FAMILIES)
    groups = {f.group for f in FAMILIES.values()}
    out: list[str] = []
    for name in (t.strip() for t in text.split(",") if t.strip()):
        if name in FAMILIES:
            chosen = [name]
        elif name in groups:
            chosen = [f.name for f in FAMILIES.values() if f.group == name]
        else:
            raise ValueError(f"no family or group {name!r} (families: {', '.join(FAMILIES)}; "
                             f"groups: {', '.join(sorted(groups))})")
        out += [n for n in chosen if n not in out]
    if not out:
        raise ValueError("--families names none")
    return out


def pick_cases(families: list[str], speeds: list[float], seeds: list[int],
               quick: bool) -> list["FamilyCase"]:
    """The grid's cases. Raises ValueError when the choice leaves none."""
    from aeb_radar_camera.tools.sim.families import FAMILIES
    from aeb_radar_camera.tools.sim.families import Case as FamilyCase

    cases: list[FamilyCase] = []
    for name in families:
        grid = [(v, p) for v, p in FAMILIES[name].grid() if not speeds or v in speeds]
        if not grid:
            continue
        if quick:
            v, p = min(grid, key=lambda vp: abs(vp[0] - QUICK_SPEED_KPH))
            cases.append(FamilyCase(name, v, p, seeds[0]))
        else:
            cases += [FamilyCase(name, v, p, s) for v, p in grid for s in seeds]
    if not cases:
        raise ValueError("no case: no family has a grid point at these speeds")
    return cases


def machine() -> str:
    model = ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            model = next((line.split(":", 1)[1].strip() for line in f
                          if line.startswith("model name")), "")
    except OSError:
        pass
    return (f"{os.cpu_count()} vCPU {model or platform.processor() or platform.machine()}, "
            f"Python {platform.python_version()}, {platform.system()}")


def config_names(paths: list[Path]) -> dict[str, Path]:
    """A name per configuration file (its stem, numbered when two share one)."""
    out: dict[str, Path] = {}
    for p in paths:
        name, n = p.stem, 2
        while name in out:
            name, n = f"{p.stem}-{n}", n + 1
        out[name] = p
    return out


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging("grid", args.log_level)
    from aeb_radar_camera.common.config.loader import ConfigError
    from aeb_radar_camera.common.service import stop_event_on_signals
    from aeb_radar_camera.tools.grid import report
    from aeb_radar_camera.tools.grid.lockstep import IDEAL, LoopConfig
    from aeb_radar_camera.tools.grid.pool import Case, print_progress, run_cases
    from aeb_radar_camera.tools.grid.score import sensor_floor
    from aeb_radar_camera.tools.sim.families import FAMILIES, listing

    if args.list:
        print(listing())
        return 0
    try:
        families = pick_families(args.families)
        speeds = [float(v) for v in args.speeds.split(",") if v.strip()]
        seeds = parse_seeds(args.seeds)
        cases = pick_cases(families, speeds, seeds, args.quick)
        if args.workers < 1:
            raise ValueError("--workers must be at least 1")
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    paths = [args.config] + ([PAPER_CONFIG] if args.paper else [])
    configs = config_names(paths)
    if args.ideal:
        if IDEAL in configs:
            print(f"error: a configuration file named {IDEAL}.toml clashes with --ideal",
                  file=sys.stderr)
            return 2
        configs[IDEAL] = args.config
    try:
        loaded = {name: LoopConfig.load(p, args.candidate if name == next(iter(configs))
                                        else None, name == IDEAL)
                  for name, p in configs.items()}
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out: Path = args.out
    runs: list[tuple[str, FamilyCase, Case]] = []
    for name, path in configs.items():
        candidate = args.candidate if name == next(iter(configs)) else None
        for c in cases:
            plot = (None if args.no_plots
                    else out / name / "plots" / c.family / f"{c.name}.png")
            runs.append((name, c, Case(c.scenario(), path, candidate,
                                       name=f"{c.name} [{name}]", plot=plot,
                                       ideal=name == IDEAL)))
    print(f"aeb grid: {len(cases)} cases x {len(configs)} configuration"
          f"{'s' if len(configs) > 1 else ''} ({', '.join(configs)}), {args.workers} "
          f"worker{'s' if args.workers > 1 else ''}; output in {out}/", file=sys.stderr)
    stop = stop_event_on_signals(grace_s=None)
    t0 = time.monotonic()
    outcomes = run_cases([r[2] for r in runs], args.workers, print_progress(), stop)
    wall = time.monotonic() - t0
    scores = [_score(runs[o.index][0], runs[o.index][1], o, loaded[runs[o.index][0]])
              for o in outcomes]
    grid = report.GridRun(
        cases=scores, configs={n: str(p) for n, p in configs.items()},
        floors={n: sensor_floor(c) for n, c in loaded.items()},
        candidate=str(args.candidate) if args.candidate else None, seeds=seeds, wall_s=wall,
        workers=args.workers, machine=machine(),
        command=shlex.join(["aeb", "grid", *(sys.argv[1:] if argv is None else argv)]),
        families={n: FAMILIES[n].description for n in families},
        interrupted=len(outcomes) < len(runs))
    try:
        md, js, maps = report.write(grid, out)
    except OSError as exc:
        print(f"error: the report could not be written: {exc}", file=sys.stderr)
        return 1
    print(report.summary(grid))
    print(f"\n{md}, {js}, {len(maps)} heat maps under {out}/<config>/heatmaps/"
          + ("" if args.no_plots else f", timeline plots under {out}/<config>/plots/"))
    errors = [s for s in scores if s.error]
    for s in errors:
        print(f"error: {s.name} [{s.config}]: {s.error}", file=sys.stderr)
    return 1 if errors or grid.interrupted else 0


def _score(config: str, c: "FamilyCase", o: "Outcome", loop: "LoopConfig") -> "CaseScore":
    from aeb_radar_camera.tools.grid.score import (
        Reach,
        failed_case,
        reasons_of,
        score_case,
        shadow_of,
    )
    from aeb_radar_camera.tools.sim.families import FAMILIES

    family = FAMILIES[c.family]
    r = o.result
    if r is None:
        return failed_case(name=c.name, family=c.family, group=family.group, kind=family.kind,
                           config=config, speed_kph=c.speed_kph, params=dict(c.params),
                           seed=c.seed, error=o.error)
    return score_case(r.samples, r.verdict, Reach.of(loop), name=c.name, family=c.family,
                      group=family.group, config=config, speed_kph=c.speed_kph,
                      params=dict(c.params), seed=c.seed, shadow=shadow_of(r.cycles),
                      reasons=reasons_of(r.cycles))


if __name__ == "__main__":
    sys.exit(main())
