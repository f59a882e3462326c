"""The evaluation as Markdown tables, in the paper's layout (Tables II-V) and side by
side for several verifiers. Ratios are printed to 3 decimals as in the paper; "-" where a
ratio has no denominator (e.g. precision when nothing passed)."""

from collections.abc import Sequence
from typing import Any


def num(v: float | None, digits: int = 3) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def _md(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def _auc_text(block: dict[str, Any]) -> str:
    """AUC [interval], marked "(too few)" where the set is too small for it."""
    if block.get("auc") is None:
        return "-"
    lo, hi = block["ci"]
    few = " (too few)" if block.get("few") else ""
    return f"{block['auc']:.3f} [{lo:.3f}, {hi:.3f}]{few}"


def tau_text(t: float) -> str:
    """A threshold: 3 decimals as the paper prints them, 3 significant digits where
    that would hide it (scores far from 0.01-1000)."""
    return f"{t:.3f}" if t == 0 or 0.01 <= abs(t) < 1000 else f"{t:.3g}"


def _kind_name(row: dict[str, Any]) -> str:
    members = ", ".join(f"{k} {n}" for k, n in sorted(row.get("members", {}).items()))
    return f"{row['kind']} ({members})" if members else row["kind"]


def warnings_text(result: dict[str, Any]) -> str:
    """The sets too small for their intervals, one line each ("" when none)."""
    lines = [f"warning: {w}" for ev in result["verifiers"].values()
             for w in ev.get("warnings", [])]
    return "\n".join(lines)


def structures_line(ev: dict[str, Any]) -> str:
    """Real structures: reported apart, never as false passes."""
    st = ev.get("real_structure") or {}
    if not st.get("n"):
        return ""
    members = ", ".join(f"{k} {n}" for k, n in sorted(st["members"].items()))
    tau = (f", {st['confirmed_tau']:.3f} at τ={ev['tau']:.3f}"
           if st.get("confirmed_tau") is not None and ev.get("tau") is not None else "")
    counted = ("counted as negatives above (--structures-as-negatives)"
               if ev.get("structures_as_negatives") else
               "not counted as negatives above: a car must not hit them, keeping them out "
               "of the brake decision is the corridor's job")
    return (f"{ev['verifier']}: real structures ({members}): {st['n']}, confirmed "
            f"{st['confirmed_operating']:.3f} at the operating point{tau}; {counted}")


def cannot_tell_line(ev: dict[str, Any]) -> str:
    """What the verifier could not tell: scored as not verified above; in fusion the
    decision's cannot-tell rule settles them ("" when it told every ROI)."""
    ct = ev.get("cannot_tell") or {}
    if not any(ct.values()):
        return ""
    return (f"{ev['verifier']}: could not tell {ct['yes']} of {ev['n_yes']} objects and "
            f"{ct['no']} of {ev['n_no']} negatives ({ct['real_structure']} real structures "
            "apart): scored as not verified here; in fusion a track the check cannot tell "
            "is the decision's (docs/fusion.md, \"Where the camera cannot tell yet\")")


def table_iii(ev: dict[str, Any]) -> str:
    """Confusion matrices and ratios at the deployed and the Youden-optimal thresholds."""
    cols: list[tuple[str, dict[str, Any]]] = []
    if ev.get("at_tau") is not None:
        cols.append((f"Deployed (τ={ev['tau']:.3f})", ev["at_tau"]))
    else:
        cols.append(("Operating point", ev["operating"]))
    if ev.get("youden") is not None:
        cols.append((f"Youden-optimal (τ={ev['youden']['tau']:.3f})", ev["youden"]))
    rows = []
    for label, key in (("True Positives", "tp"), ("False Positives", "fp"),
                       ("True Negatives", "tn"), ("False Negatives", "fn")):
        rows.append([label] + [str(c[key]) for _, c in cols])
    for label, key in (("Precision", "precision"), ("Recall", "recall"), ("F1 Score", "f1"),
                       ("Accuracy", "accuracy")):
        rows.append([label] + [num(c[key]) for _, c in cols])
    rows.append(["AUC"] + [num(ev.get("auc")) for _ in cols])
    title = (f"Table III: {ev['verifier']} at the deployed and Youden-optimal thresholds "
             f"(n={ev['n']}: {ev['n_yes']} YES, {ev['n_no']} NO)")
    return title + "\n\n" + _md(["Metric"] + [name for name, _ in cols], rows)


def table_iv(ev: dict[str, Any]) -> str:
    """The threshold sweep."""
    youden = ev["youden"]["tau"] if ev.get("youden") else None
    rows = []
    for row in ev["sweep"]:
        notes = []
        if ev.get("tau") is not None and abs(row["tau"] - ev["tau"]) < 1e-12:
            notes.append("deployed")
        if youden is not None and tau_text(row["tau"]) == tau_text(youden):
            notes.append("Youden-optimal")
        rows.append([tau_text(row["tau"]), num(row["precision"]), num(row["recall"]),
                     num(row["f1"]), num(row["fpr"]), ", ".join(notes)])
    basis = f" (thresholds: {ev['sweep_basis']})" if ev.get("sweep_basis") else ""
    return (f"Table IV: {ev['verifier']}, threshold sensitivity{basis}\n\n"
            + _md(["Threshold", "Precision", "Recall", "F1", "FPR", "Notes"], rows))


def table_v(ev: dict[str, Any], stratum: str = "group") -> str:
    """Precision, recall and F1 per stratum at the deployed threshold (the operating
    point for a verifier without one), with every ROI combined last."""
    at = "at_tau" if ev.get("at_tau") is not None else "operating"
    rows = []
    for row in ev["strata"].get(stratum, []):
        c = row[at]
        rows.append([row["name"], str(row["n"]), num(c["precision"]), num(c["recall"]),
                     num(c["f1"])])
    c = ev[at]
    rows.append(["All combined", str(ev["n"]), num(c["precision"]), num(c["recall"]),
                 num(c["f1"])])
    where = f"τ={ev['tau']:.3f}" if at == "at_tau" else "the operating point"
    return (f"Table V: {ev['verifier']} per {stratum} at {where}\n\n"
            + _md(["Condition", "n", "Precision", "Recall", "F1"], rows))


def table_ii(t: dict[str, Any]) -> str:
    """ROI vs full-frame processing time."""
    r, f = t.get("roi_us"), t.get("frame_us")

    def ms(d: dict[str, float] | None, key: str) -> str:
        return "-" if d is None else f"{d[key] / 1000:.3f}"

    def ratio(key: str, word: str) -> str:
        v = t.get(key)
        return "-" if v is None else f"{v:.1f}x {word}"

    def area(key: str) -> str:
        v = t.get(key)
        return "-" if v is None else f"{v:.1f}%"

    rows = [["Mean latency (ms)", ms(r, "mean"), ms(f, "mean"), ratio("mean_ratio", "faster")],
            ["Std. deviation (ms)", ms(r, "std"), ms(f, "std"), "-"],
            ["p95 latency (ms)", ms(r, "p95"), ms(f, "p95"), ratio("p95_ratio", "lower")],
            ["Samples", str(r["n"]) if r else "0", str(f["n"]) if f else "0", "-"],
            ["Pixels near 8 m (% of frame)", area("area_pct_8m"), "100%", "-"],
            ["Pixels near 25 m (% of frame)", area("area_pct_25m"), "100%", "-"],
            ["Frames / sessions", f"{t['frames']} / {t['sessions']}", "-", "-"]]
    return (f"Table II: {t['verifier']} per ROI vs Canny on the full frame\n\n"
            + _md(["Metric", "ROI patch", "Full frame", "Improvement"], rows))


def negative_kinds_table(ev: dict[str, Any]) -> str:
    """Every YES against each kind of NO, the kinds named for what they are; for real
    structures the share passing is the share confirmed (as it should be)."""
    rows = []
    for row in ev["negative_kinds"]:
        name = _kind_name(row) + (": passing = confirmed" if row.get("real_structure")
                                  else "")
        rows.append([name, str(row["n_no"]), _auc_text(row),
                     num(row["pass_rate_operating"]), num(row.get("cannot_tell_rate")),
                     num(row.get("pass_rate_tau")), num(row["median_score"])])
    tau = f"τ={ev['tau']:.3f}" if ev.get("tau") is not None else "τ"
    text = (f"{ev['verifier']}: all YES against each kind of NO "
            f"({round(100 * ev.get('level', 0.95))}% CI by {ev['ci_group']})\n\n"
            + _md(["negatives", "n", "AUC [CI]", "pass rate at operating point",
                   "cannot tell", f"pass rate at {tau}", "median score"], rows))
    lines = [line for line in (structures_line(ev), cannot_tell_line(ev)) if line]
    return text + "".join("\n\n" + line for line in lines)


def class_table(ev: dict[str, Any]) -> str:
    """Recall per object class."""
    rows = [[row["class"], str(row["n"]), num(row["recall_operating"]),
             str(row.get("cannot_tell", 0)), num(row.get("recall_tau")),
             num(row["median_score"])]
            for row in ev["recall_by_class"]]
    tau = f"τ={ev['tau']:.3f}" if ev.get("tau") is not None else "τ"
    return (f"{ev['verifier']}: recall per object class\n\n"
            + _md(["class", "n", "recall at operating point", "cannot tell",
                   f"recall at {tau}", "median score"], rows))


def compare_table(evs: Sequence[dict[str, Any]]) -> str:
    """Several verifiers on the same ROIs."""
    kinds = sorted({k["kind"] for ev in evs for k in ev["negative_kinds"]})
    header = ["verifier", "n YES/NO", "n/a", "AUC [CI]", "recall", "precision", "FPR",
              "Youden τ", "recall@Y", "FPR@Y", "µs/ROI"] + [f"AUC vs {k}" for k in kinds]
    rows = []
    for ev in evs:
        op = ev["operating"]
        y = ev.get("youden") or {}
        t = ev["timing_us"]["roi"]
        by_kind = {k["kind"]: k for k in ev["negative_kinds"]}
        rows.append([ev["verifier"], f"{ev['n_yes']}/{ev['n_no']}",
                     str(ev["counts"]["not_applicable"]), _auc_text(ev),
                     num(op["recall"]), num(op["precision"]), num(op["fpr"]),
                     num(y.get("tau"), 4), num(y.get("recall")), num(y.get("fpr")),
                     "-" if t is None else f"{t['mean']:.0f}"]
                    + [_auc_text(by_kind[k]) if k in by_kind else "-" for k in kinds])
    structures = [line for ev in evs for line in (structures_line(ev), cannot_tell_line(ev))
                  if line]
    return ("Verifiers side by side on the same ROIs (recall, precision, FPR at each "
            "verifier's own operating point; @Y: at its Youden-optimal threshold; n/a: "
            "ROIs it cannot judge, e.g. no depth; the negatives are those a camera may "
            "reject: real structures apart)\n\n"
            + _md(header, rows) + "".join("\n\n" + line for line in structures))


def compare_kinds_table(evs: Sequence[dict[str, Any]]) -> str:
    """Every verifier against each kind of negative: AUC, and at its operating point
    recall, the share of those negatives that pass, precision against them alone."""
    rows = []
    for ev in evs:
        for k in ev["negative_kinds"]:
            op = k["operating"]
            rows.append([ev["verifier"], _kind_name(k), f"{k['n_yes']}/{k['n_no']}",
                         _auc_text(k), num(op["recall"]), num(op["fpr"]),
                         num(op["precision"])])
    return ("Per kind of negative (all YES against the NOs of that kind; at each "
            "verifier's operating point; for real structures \"negatives passing\" is "
            "the share confirmed, as it should be)\n\n"
            + _md(["verifier", "negatives", "n YES/NO", "AUC [CI]", "recall",
                   "negatives passing", "precision"], rows))


def full_report(result: dict[str, Any], stratum: str | None = None) -> str:
    """Every table of an evaluation, one verifier after the other."""
    parts = []
    warned = warnings_text(result)
    if warned:
        parts.append(warned)
    evs = list(result["verifiers"].values())
    if len(evs) > 1:
        parts.append(compare_table(evs))
        parts.append(compare_kinds_table(evs))
    for ev in evs:
        parts.append(f"## {ev['verifier']} {ev['params']}")
        parts.append(table_iii(ev))
        parts.append(table_iv(ev))
        parts.append(negative_kinds_table(ev))
        if stratum is not None:
            parts.append(table_v(ev, stratum))
        else:
            for name in ("group", "lighting", "range"):
                if name in ev["strata"]:
                    parts.append(table_v(ev, name))
            parts.append(class_table(ev))
    for name, why in result["skipped"].items():
        parts.append(f"{name}: not evaluated ({why})")
    if result["timing"].get("roi_us") or result["timing"].get("frame_us"):
        parts.append(table_ii(result["timing"]))
    return "\n\n".join(parts) + "\n"
