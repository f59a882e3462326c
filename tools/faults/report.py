"""The fault table: per fault, injections, responses within bound, p50 / max response
and recovery times, anything lost; as Markdown, JSON and a PNG."""

import json
import platform
import statistics
from pathlib import Path
from typing import Any

from aeb_radar_camera.tools.faults.catalogue import Outcome
from aeb_radar_camera.tools.faults.harness import Record, RunInfo


def _stats(values: list[float]) -> tuple[float | None, float | None]:
    if not values:
        return None, None
    return statistics.median(values), max(values)


def rows(records: list[Record]) -> list[dict[str, Any]]:
    out = []
    for rec in records:
        times = [o.response_ms for o in rec.outcomes if o.response_ms is not None]
        p50, mx = _stats(times)
        r50, rmax = _stats(rec.recover_s)
        failures = [o.detail for o in rec.outcomes if not o.ok]
        bounds = [o.bound_ms for o in rec.outcomes if o.bound_ms is not None]
        out.append({
            "fault": rec.fault, "required": rec.required, "injections": len(rec.outcomes),
            "within_bound": sum(o.ok for o in rec.outcomes),
            "no_response": sum(o.response_ms is None for o in rec.outcomes),
            "bound_ms": max(bounds) if bounds else None, "p50_ms": p50, "max_ms": mx,
            "recover_p50_s": r50, "recover_max_s": rmax,
            "lost": sum(o.lost for o in rec.outcomes), "unrecovered": rec.unrecovered,
            "skipped": rec.skipped, "first_failures": failures[:3],
            "detail": rec.outcomes[-1].detail if rec.outcomes else "",
        })
    return out


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v:.1f}"


def _s(v: float | None) -> str:
    return "-" if v is None else f"{v:.1f}"


def markdown(table: list[dict[str, Any]], info: RunInfo) -> str:
    runs = "; ".join(f"{r['mode']}: {r['rounds_done']} rounds in {r['seconds'] / 60:.1f} min"
                     for r in info.runs)
    head = (f"{len(info.runs)} runs ({runs})" if info.runs else
            f"mode {info.mode}: {info.rounds_done} of {info.rounds_planned} rounds in "
            f"{info.seconds / 60:.1f} min")
    gc_pause = (f"; the harness's longest garbage collection {info.gc_pause_max_ms:.0f} ms"
                if info.gc_pause_max_ms else "")
    lines = [f"{head}; link cut: {info.link}; scheduling: {info.scheduling}{gc_pause}"
             + (f"; stopped early: {info.stopped_early}" if info.stopped_early else ""), "",
             "| fault | required response | injections | within bound | bound ms | p50 ms "
             "| max ms | recovery p50 / max s | lost |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in table:
        if r["skipped"]:
            lines.append(f"| {r['fault']} | {r['required']} | skipped: {r['skipped']} "
                         "| | | | | | |")
            continue
        lines.append(f"| {r['fault']} | {r['required']} | {r['injections']} | "
                     f"{r['within_bound']} | {_ms(r['bound_ms'])} | {_ms(r['p50_ms'])} | "
                     f"{_ms(r['max_ms'])} | "
                     f"{_s(r['recover_p50_s'])} / {_s(r['recover_max_s'])} | {r['lost']} |")
    failed = [r for r in table if r["first_failures"]]
    if failed:
        lines += ["", "Failures (first of each fault):", ""]
        lines += [f"- {r['fault']}: {r['first_failures'][0]}" for r in failed]
    if info.unexpected_exits:
        lines += ["", "Processes that exited without being killed: "
                  + "; ".join(info.unexpected_exits[:10])]
    return "\n".join(lines) + "\n"


def plot(table: list[dict[str, Any]], records: list[Record], path: Path) -> Path | None:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    shown = [(r, rec) for r, rec in zip(table, records, strict=True) if rec.outcomes]
    fig, ax = plt.subplots(figsize=(11, 0.45 * len(shown) + 1.5))
    for i, (r, rec) in enumerate(shown):
        times = [o.response_ms for o in rec.outcomes if o.response_ms is not None]
        ok = [o.response_ms for o in rec.outcomes if o.ok and o.response_ms is not None]
        bad = [o.response_ms for o in rec.outcomes if not o.ok and o.response_ms is not None]
        ax.scatter(ok, [i] * len(ok), s=8, color="tab:green", alpha=0.5)
        ax.scatter(bad, [i] * len(bad), s=14, color="tab:red", marker="x")
        if times:
            ax.plot([r["p50_ms"]], [i], marker="|", markersize=14, color="black")
        if r["bound_ms"] is not None:
            ax.plot([r["bound_ms"]], [i], marker="|", markersize=10, color="tab:red")
        if r["no_response"]:
            ax.annotate(f"{r['no_response']} without response", (0.02, i),
                        xycoords=("axes fraction", "data"), va="center", fontsize=7,
                        color="tab:red")
    ax.set_yticks(range(len(shown)))
    ax.set_yticklabels([f"{r['fault']} ({r['within_bound']}/{r['injections']})"
                        for r, _ in shown], fontsize=8)
    ax.set_xscale("log")
    ax.set_xlabel("response time, ms (log): green met, red x failed (late, or another "
                  "requirement broken); black | median, red | bound")
    ax.invert_yaxis()
    ax.grid(True, axis="x", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write(out: Path, records: list[Record], info: RunInfo) -> tuple[Path, Path, Path | None]:
    out.mkdir(parents=True, exist_ok=True)
    table = rows(records)
    md = out / "faults.md"
    md.write_text(markdown(table, info))
    js = out / "faults.json"
    js.write_text(json.dumps({
        "mode": info.mode, "rounds_planned": info.rounds_planned,
        "rounds_done": info.rounds_done, "seconds": round(info.seconds, 1),
        "link": info.link, "scheduling": info.scheduling,
        "gc_pause_max_ms": round(info.gc_pause_max_ms, 1),
        "stopped_early": info.stopped_early,
        "unexpected_exits": info.unexpected_exits,
        "machine": {"node": platform.node(), "cpus": _cpus(), "python": platform.python_version(),
                    "kernel": platform.release()},
        "faults": table,
        "runs": info.runs or [_run_dict(info)],
        "outcomes": {rec.fault: {"required": rec.required, "skipped": rec.skipped,
                                 "unrecovered": rec.unrecovered, "recover_s": rec.recover_s,
                                 "list": [[o.ok, o.response_ms, o.lost, o.bound_ms,
                                           o.detail[:120]] for o in rec.outcomes]}
                     for rec in records},
    }, indent=1))
    png = plot(table, records, out / "faults.png")
    return md, js, png


def _run_dict(info: RunInfo) -> dict[str, Any]:
    return {"mode": info.mode, "rounds_done": info.rounds_done, "seconds": info.seconds,
            "stopped_early": info.stopped_early, "link": info.link,
            "scheduling": info.scheduling, "gc_pause_max_ms": info.gc_pause_max_ms}


def combine(paths: list[Path]) -> tuple[list[Record], RunInfo]:
    """The records of several runs' faults.json as one table (a fault run in several
    runs has all their injections). Raises OSError, ValueError (not a faults.json)."""
    records: dict[str, Record] = {}
    info = RunInfo("combined", 0)
    for path in paths:
        data = json.loads(path.read_text())
        for name, o in data["outcomes"].items():
            rec = records.setdefault(name, Record(name, o["required"]))
            if not o["list"]:
                if not rec.outcomes:
                    rec.skipped = rec.skipped or o["skipped"]
                continue
            rec.skipped = ""
            rec.outcomes += [Outcome(ok, resp, detail, lost, bound)
                             for ok, resp, lost, bound, detail in o["list"]]
            rec.recover_s += o["recover_s"]
            rec.unrecovered += o["unrecovered"]
        info.runs += data.get("runs", [])
        info.rounds_planned += data["rounds_planned"]
        info.rounds_done = max(info.rounds_done, data["rounds_done"])
        info.seconds += data["seconds"]
        info.unexpected_exits += data["unexpected_exits"]
        info.link = info.link or data["link"]
        info.scheduling = data.get("scheduling", info.scheduling)
        info.gc_pause_max_ms = max(info.gc_pause_max_ms, data.get("gc_pause_max_ms", 0.0))
        if data["stopped_early"]:
            info.stopped_early += f"{path.parent.name}: {data['stopped_early']} "
    return list(records.values()), info


def _cpus() -> int:
    import os
    return len(os.sched_getaffinity(0))
