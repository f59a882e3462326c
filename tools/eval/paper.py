"""A label set and score list constructed to the paper's published numbers, to show that
the tool reproduces its tables exactly (`aeb eval paper`).

The paper (Tables III-V) gives, for 317 labelled ROIs (159 YES, 158 NO; 3 ambiguous
left out), the confusion matrices at tau 0.025 and 0.080, precision and recall at six
thresholds, precision/recall/F1 per lighting group at 0.025, AUC 0.898, and 0.080 as the
Youden-optimal threshold. Those numbers fix how many YES and NO ROIs lie between each
pair of neighbouring thresholds (and, with Table V, how many per group); only the order
inside each band is free. Here it is chosen so that the AUC is 0.898 and the
Youden-optimal threshold is exactly 0.080. The scores are constructed, not measured:
they reproduce the tables, nothing more.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aeb_radar_camera.tools.eval.labels import AMBIGUOUS, NO, YES, Label, write_labels

# (low, high, YES, NO, order) per band of scores between the paper's thresholds, from the
# counts that Tables III and IV imply (e.g. 159 YES >= 0.010, 158 >= 0.025, 131 >=
# 0.050, 130 >= 0.080, 125 >= 0.100, 74 >= 0.150). `order` places the YES among the NO
# inside the band (ascending score): see _band_order.
BANDS = (
    (0.000, 0.010, 0, 15, "as is"),
    (0.010, 0.025, 1, 63, "yes on top"),
    (0.025, 0.050, 27, 53, "wins"),
    (0.050, 0.080, 1, 3, "yes at bottom"),
    (0.080, 0.100, 5, 0, "as is"),
    (0.100, 0.150, 51, 19, "yes at bottom"),
    (0.150, 0.400, 74, 5, "yes on top"),
)
# Pairs (YES above NO) wanted inside the band marked "wins": with the pairs across bands
# (fixed by the counts) and the others inside bands, AUC = 22,559 / 25,122 = 0.898.
BAND_WINS = 1048
# Inside that band the NOs below a YES never lead by more than this: the Youden index
# stays below its value at 0.080.
MAX_LEAD = 27

# Table V at tau 0.025: (group, sessions, TP, FP, TN, FN); the only split consistent
# with Table III's totals and the rounded precision, recall and F1 of each group.
GROUPS = (
    ("Controlled daytime (sessions 27-63)", "controlled", range(27, 64), 63, 19, 17, 0),
    ("Daytime naturalistic (sessions 0-26)", "naturalistic", range(0, 27), 81, 23, 21, 1),
    ("Evening / low-light (sessions 64-71)", "evening", range(64, 72), 14, 38, 40, 0),
)
N_AMBIGUOUS = 3
TAU_DEPLOYED = 0.025


@dataclass(frozen=True)
class Item:
    roi_id: str
    score: float
    label: str
    session: str


def _band_order(n_yes: int, n_no: int, how: str) -> str:
    """The band's labels in ascending score, "Y"/"N"."""
    if how == "yes on top":
        return "N" * n_no + "Y" * n_yes
    if how == "yes at bottom" or how == "as is":
        return "Y" * n_yes + "N" * n_no
    # NOs below the k-th YES: as many as allowed (lead <= MAX_LEAD), then fewer from the
    # lowest YES upward until the band holds exactly BAND_WINS pairs.
    below = [min(n_no, MAX_LEAD + k) for k in range(n_yes)]
    excess = sum(below) - BAND_WINS
    if excess < 0:
        raise AssertionError("BAND_WINS is out of reach")
    for k in range(n_yes):
        cut = min(excess, below[k])
        below[k] -= cut
        excess -= cut
    out, placed = [], 0
    for c in below:
        out.append("N" * (c - placed) + "Y")
        placed = c
    return "".join(out) + "N" * (n_no - placed)


def items() -> list[Item]:
    """317 scored, labelled ROIs and 3 ambiguous ones, with sessions by group."""
    scored: list[tuple[float, str]] = []
    for lo, hi, n_yes, n_no, how in BANDS:
        order = _band_order(n_yes, n_no, how)
        for k, c in enumerate(order):
            # The first item of a band sits exactly on its threshold (score >= tau passes).
            scored.append((lo + (hi - lo) * k / len(order), YES if c == "Y" else NO))
    # Sessions: each group gets its TP/FN/FP/TN counts at tau 0.025; within a cell the
    # ROIs are spread over the group's sessions.
    cells: dict[tuple[str, bool], list[tuple[str, range]]] = {}
    for _, name, sessions, tp, fp, tn, fn in GROUPS:
        for key, count in (((YES, True), tp), ((YES, False), fn), ((NO, True), fp),
                           ((NO, False), tn)):
            cells.setdefault(key, []).extend([(name, sessions)] * count)
    rng = np.random.default_rng(317)
    for members in cells.values():
        rng.shuffle(members)
    taken: dict[tuple[str, bool], int] = {}
    out = []
    for i, (score, label) in enumerate(scored):
        key = (label, score >= TAU_DEPLOYED)
        j = taken.get(key, 0)
        taken[key] = j + 1
        name, sessions = cells[key][j]
        session = f"{name}-{sessions[j % len(sessions)]:02d}"
        out.append(Item(f"paper-{i:03d}", score, label, session))
    for k in range(N_AMBIGUOUS):
        out.append(Item(f"paper-ambiguous-{k}", 0.03 + 0.01 * k, AMBIGUOUS,
                        f"naturalistic-{k:02d}"))
    return out


def group_args() -> list[str]:
    """The --group options that name the paper's session groups (Table V)."""
    return [f"{title}={name}-*" for title, name, *_ in GROUPS]


def write(folder: Path, who: str = "paper-construction") -> tuple[Path, Path]:
    """labels.tsv and scores.csv of the constructed set; returns their paths."""
    folder.mkdir(parents=True, exist_ok=True)
    data = items()
    labels = folder / "labels.tsv"
    write_labels(labels, [Label(it.roi_id, it.label, who, "2026-01-01T00:00:00Z")
                          for it in data])
    scores = folder / "scores.csv"
    with open(scores, "w", encoding="utf-8") as f:
        f.write("id,score,session\n")
        for it in data:
            f.write(f"{it.roi_id},{it.score!r},{it.session}\n")
    return labels, scores
