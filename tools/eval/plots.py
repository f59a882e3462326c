"""PNG figures of an evaluation (the paper's Figs. 3 and 4 and more): ROC curves with
their operating points, confusion matrices, score histograms per class, and ROI vs
full-frame timing."""

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from aeb_radar_camera.tools.eval.labels import YES
from aeb_radar_camera.tools.eval.records import RoiRecord


def _save(fig: Any, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _roc_points(ev: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    return np.array(ev["roc"]["fpr"]), np.array(ev["roc"]["tpr"])


def roc_plot(result: dict[str, Any], path: Path, title: str = "") -> Path:
    """Left: every verifier against all negatives, with its operating point (red) and
    Youden-optimal point (blue). Right: the first verifier against each kind of
    negative."""
    evs = [ev for ev in result["verifiers"].values() if ev.get("roc")]
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.5))
    ax = axes[0]
    for ev in evs:
        fpr, tpr = _roc_points(ev)
        lo, hi = ev["ci"]
        ax.plot(fpr, tpr, lw=1.6, label=f"{ev['verifier']}: AUC {ev['auc']:.3f} "
                                         f"[{lo:.3f}, {hi:.3f}]")
        op = ev["at_tau"] if ev.get("at_tau") else ev["operating"]
        ax.plot(op["fpr"] or 0.0, op["recall"] or 0.0, "o", color="red", ms=7)
        y = ev["youden"]
        ax.plot(y["fpr"] or 0.0, y["recall"] or 0.0, "s", color="blue", ms=6)
    ax.plot([0, 1], [0, 1], "k:", lw=0.8)
    ax.set_title("all negatives (red: deployed threshold, blue: Youden-optimal)",
                 fontsize=9)
    _roc_axes(ax)
    ax = axes[1]
    if evs:
        first = evs[0]
        ax.set_title(f"{first['verifier']} per kind of negative", fontsize=9)
        for k in first["negative_kinds"]:
            if k.get("roc"):
                lo, hi = k["ci"]
                ax.plot(k["roc"]["fpr"], k["roc"]["tpr"], lw=1.6,
                        label=f"vs {k['kind']} (n {k['n_no']}): AUC {k['auc']:.3f} "
                              f"[{lo:.3f}, {hi:.3f}]")
    ax.plot([0, 1], [0, 1], "k:", lw=0.8)
    _roc_axes(ax)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def _roc_axes(ax: Any) -> None:
    ax.set_xlabel("false positive rate (negatives passed)")
    ax.set_ylabel("true positive rate (recall)")
    ax.set_xlim(-0.01, 1.01)
    ax.set_ylim(-0.01, 1.01)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)


def confusion_plot(result: dict[str, Any], path: Path) -> Path:
    """Per verifier: the confusion matrix at the deployed threshold (or its operating
    point) and at its Youden-optimal threshold."""
    evs = [ev for ev in result["verifiers"].values() if ev.get("youden")]
    fig, axes = plt.subplots(max(1, len(evs)), 2, figsize=(8, 3.6 * max(1, len(evs))),
                             squeeze=False)
    for row, ev in zip(axes, evs, strict=False):
        first = (("deployed τ={:.3f}".format(ev["tau"]), ev["at_tau"]) if ev.get("at_tau")
                 else ("operating point", ev["operating"]))
        cols = [first, (f"Youden-optimal τ={ev['youden']['tau']:.3f}", ev["youden"])]
        for ax, (name, c) in zip(row, cols, strict=True):
            m = np.array([[c["tp"], c["fn"]], [c["fp"], c["tn"]]])
            ax.imshow(m, cmap="Blues")
            for (i, j), v in np.ndenumerate(m):
                ax.text(j, i, str(v), ha="center", va="center", fontsize=13,
                        color="white" if v > m.max() / 2 else "black")
            ax.set_xticks([0, 1], ["passed", "rejected"])
            ax.set_yticks([0, 1], ["YES", "NO"])
            ax.set_title(f"{ev['verifier']}, {name}", fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


def density_plot(records: list[RoiRecord], labels: dict[str, str], path: Path,
                 verifier: str = "edge_density", taus: tuple[float, ...] = (0.025, 0.08)
                 ) -> Path:
    """Histograms of a verifier's score: YES, and NO per kind of negative."""
    groups: dict[str, list[float]] = {}
    for r in records:
        label = labels.get(r.id)
        sc = r.scores.get(verifier)
        if label not in ("YES", "NO") or sc is None or sc.score is None:
            continue
        groups.setdefault("YES" if label == YES else f"NO ({r.kind})", []).append(sc.score)
    fig, ax = plt.subplots(figsize=(8, 4.5))
    hi = max((max(v) for v in groups.values()), default=1.0)
    bins = np.linspace(0.0, max(hi, 1e-3), 40).tolist()
    for name, vals in sorted(groups.items()):
        ax.hist(vals, bins=bins, histtype="step", lw=1.8, density=True,
                label=f"{name}: n {len(vals)}, median {np.median(vals):.3f}")
    for t in taus:
        ax.axvline(t, color="grey", ls="--", lw=0.9)
        ax.text(t, ax.get_ylim()[1] * 0.95, f" τ={t:g}", fontsize=8, color="grey")
    ax.set_xlabel(f"{verifier} score")
    ax.set_ylabel("density")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return _save(fig, path)


def timing_plot(records: list[RoiRecord], path: Path, verifier: str = "edge_density"
                ) -> Path:
    """Table II as a figure: mean (bars) and 5th-95th percentile (box) per ROI and per
    full frame."""
    roi = [r.scores[verifier].us / 1000 for r in records
           if verifier in r.scores and r.scores[verifier].score is not None]
    full = [r.frame_canny_us / 1000 for r in records if r.frame_canny_us is not None]
    fig, axes = plt.subplots(1, 2, figsize=(9, 4))
    data = [(n, v) for n, v in (("ROI patch", roi), ("full frame", full)) if v]
    axes[0].bar([n for n, _ in data], [float(np.mean(v)) for _, v in data],
                color=["tab:green", "tab:grey"][:len(data)])
    axes[0].set_ylabel("mean time (ms)")
    if data:
        axes[1].boxplot([v for _, v in data], whis=(5, 95), showfliers=False)
        axes[1].set_xticks(range(1, len(data) + 1), [n for n, _ in data])
    axes[1].set_ylabel("time (ms), box 25-75%, whiskers 5-95%")
    fig.suptitle(f"{verifier}: ROI vs full-frame time (this machine)", fontsize=10)
    fig.tight_layout()
    return _save(fig, path)
