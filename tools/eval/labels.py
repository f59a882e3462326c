"""The label file: one line per ROI, tab-separated, appended as a person labels.

    # aeb labels v1: id<TAB>label<TAB>who<TAB>when (UTC, ISO 8601)
    drive1:1718000000123456789:front:17<TAB>YES<TAB>ana<TAB>2025-06-10T09:12:01Z

`label` is YES, NO or ambiguous (ambiguous ROIs are left out of the metrics, as the
paper left its three out). A later line for the same id replaces an earlier one, so a
file is only ever appended to and a session can stop at any moment and resume. Data sets
with ground truth are labelled by their annotations (`who` names the annotation).
"""

import datetime
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from aeb_radar_camera.tools.eval.records import RoiRecord

YES, NO, AMBIGUOUS = "YES", "NO", "ambiguous"
VALUES = (YES, NO, AMBIGUOUS)
HEADER = "# aeb labels v1: id\tlabel\twho\twhen (UTC, ISO 8601)\n"


class LabelFileError(ValueError):
    """A malformed label file; the message names the file and line."""


@dataclass(frozen=True)
class Label:
    roi_id: str
    value: str
    who: str
    when: str


def now_utc() -> str:
    return datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def parse_line(line: str, where: str) -> Label | None:
    """One line, or None for a comment or a blank line. Raises LabelFileError."""
    text = line.rstrip("\n")
    if not text.strip() or text.startswith("#"):
        return None
    parts = text.split("\t")
    if len(parts) != 4:
        raise LabelFileError(f"{where}: expected 4 tab-separated fields (id, label, who, "
                             f"when), got {len(parts)}")
    roi_id, value, who, when = parts
    if value not in VALUES:
        raise LabelFileError(f"{where}: label {value!r} is not one of {', '.join(VALUES)}")
    if not roi_id:
        raise LabelFileError(f"{where}: empty ROI id")
    return Label(roi_id, value, who, when)


def read_labels(path: str | Path) -> dict[str, Label]:
    """id -> its latest label. A missing file is an empty set. Raises LabelFileError."""
    p = Path(path)
    if not p.exists():
        return {}
    out: dict[str, Label] = {}
    with open(p, encoding="utf-8") as f:
        for i, line in enumerate(f, 1):
            label = parse_line(line, f"{p}:{i}")
            if label is not None:
                out[label.roi_id] = label
    return out


def format_line(label: Label) -> str:
    for field in (label.roi_id, label.who, label.when):
        if "\t" in field or "\n" in field:
            raise ValueError(f"label field {field!r} holds a tab or a newline")
    if label.value not in VALUES:
        raise ValueError(f"label {label.value!r} is not one of {', '.join(VALUES)}")
    return f"{label.roi_id}\t{label.value}\t{label.who}\t{label.when}\n"


class LabelWriter:
    """Appends labels, each flushed to disk before `add` returns (a crash loses nothing
    that was acknowledged)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        new = not self.path.exists() or self.path.stat().st_size == 0
        self._f = open(self.path, "a", encoding="utf-8")  # noqa: SIM115 (closed in close())
        if new:
            self._f.write(HEADER)
            self._f.flush()

    def add(self, label: Label) -> None:
        self._f.write(format_line(label))
        self._f.flush()
        os.fsync(self._f.fileno())

    def close(self) -> None:
        self._f.close()


def write_labels(path: str | Path, labels: Iterable[Label]) -> int:
    """Write a whole label file (replacing it); returns the number of lines."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    n = 0
    with open(p, "w", encoding="utf-8") as f:
        f.write(HEADER)
        for label in labels:
            f.write(format_line(label))
            n += 1
    return n


def truth_labels(records: Iterable[RoiRecord], who: str, when: str = "") -> list[Label]:
    """Labels of the records that carry ground truth (a data set's annotations)."""
    stamp = when or now_utc()
    return [Label(r.id, r.truth, who, stamp) for r in records if r.truth in (YES, NO)]


def resolve(records: Iterable[RoiRecord], labels: dict[str, Label] | None
            ) -> dict[str, str]:
    """id -> YES / NO / ambiguous: the label file's entry, else the record's ground
    truth; ids with neither are left out."""
    out: dict[str, str] = {}
    for r in records:
        given = labels.get(r.id) if labels else None
        if given is not None:
            out[r.id] = given.value
        elif r.truth in (YES, NO):
            out[r.id] = r.truth
    return out
