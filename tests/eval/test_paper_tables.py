"""Exactness: from a label set and score list constructed to the paper's numbers, the
tool prints the paper's Table III, Table IV and Table V with its figures."""

import json

from aeb_radar_camera.tools.eval import paper
from aeb_radar_camera.tools.eval.cli import main

# The paper's Table III (metric: deployed tau 0.025, Youden-optimal tau 0.080).
TABLE_III = {
    "True Positives": ("158", "130"), "False Positives": ("80", "24"),
    "True Negatives": ("78", "134"), "False Negatives": ("1", "29"),
    "Precision": ("0.664", "0.844"), "Recall": ("0.994", "0.818"),
    "F1 Score": ("0.796", "0.831"), "Accuracy": ("0.744", "0.833"),
    "AUC": ("0.898", "0.898"),
}
# Table IV: threshold -> precision, recall, F1.
TABLE_IV = {"0.010": ("0.526", "1.000", "0.690"), "0.025": ("0.664", "0.994", "0.796"),
            "0.050": ("0.829", "0.824", "0.826"), "0.080": ("0.844", "0.818", "0.831"),
            "0.100": ("0.839", "0.786", "0.812"), "0.150": ("0.937", "0.465", "0.622")}
# Table V: condition -> n, precision, recall, F1.
TABLE_V = {"Controlled daytime (sessions 27-63)": ("99", "0.768", "1.000", "0.869"),
           "Daytime naturalistic (sessions 0-26)": ("126", "0.779", "0.988", "0.871"),
           "Evening / low-light (sessions 64-71)": ("92", "0.269", "1.000", "0.424"),
           "All combined": ("317", "0.664", "0.994", "0.796")}


def rows(text, title):
    """The cells of the Markdown table under the line that starts with `title`."""
    lines = text.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith(title))
    out = {}
    for ln in lines[start + 4:]:
        if not ln.startswith("|"):
            break
        cells = [c.strip() for c in ln.strip("|").split("|")]
        out[cells[0]] = tuple(cells[1:])
    return out


def test_the_constructed_set_has_the_papers_counts():
    items = paper.items()
    labels = [i.label for i in items]
    assert (labels.count("YES"), labels.count("NO"), labels.count("ambiguous")) == (159, 158, 3)


def test_aeb_eval_paper_prints_tables_iii_iv_and_v_exactly(tmp_path, capsys):
    assert main(["paper", "--out", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "n=317: 159 YES, 158 NO" in text
    assert "| Metric | Deployed (τ=0.025) | Youden-optimal (τ=0.080) |" in text
    assert rows(text, "Table III") == TABLE_III
    iv = rows(text, "Table IV")
    assert {t: v[:3] for t, v in iv.items()} == TABLE_IV
    assert iv["0.025"][4] == "deployed" and iv["0.080"][4] == "Youden-optimal"
    assert rows(text, "Table V") == TABLE_V
    # The same figures in the JSON report, unrounded.
    report = json.loads((tmp_path / "report.json").read_text())
    ev = report["verifiers"]["scores"]
    assert ev["youden"]["tau"] == 0.08
    assert ev["counts"]["ambiguous"] == 3
    assert (ev["at_tau"]["tp"], ev["at_tau"]["fp"]) == (158, 80)
    assert (tmp_path / "roc.png").read_bytes()[:4] == b"\x89PNG"


def test_report_from_label_file_and_score_csv_gives_the_same_tables(tmp_path, capsys):
    labels, scores = paper.write(tmp_path)
    argv = ["report", "--scores", str(scores), "--labels", str(labels), "--tau", "0.025",
            "--out", str(tmp_path / "r"), "--no-plots", "--boot", "200"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert rows(text, "Table III") == TABLE_III
    # A threshold the paper did not print is computed the same way.
    assert main([*argv[:-2], "--taus", "0.2"]) == 0
    assert list(rows(capsys.readouterr().out, "Table IV")) == ["0.200"]
