"""The ROI set: one record per ROI with what a labeller and the tables need, and every
verifier's score; stored as JSON lines (`rois.jsonl`) beside a `run.json`.

A record never holds pixels: `frame` says how to rebuild the exact grey frame the
verifiers saw (a message in a recording, or a data-set image resampled and JPEG-coded),
so a data set is read in place and never copied.
"""

import os
from collections.abc import Iterable, Iterator
from pathlib import Path

import msgspec

ROIS_FILE = "rois.jsonl"
RUN_FILE = "run.json"

# Kinds of ROI: what stands at the ROI by construction (the label says YES or NO).
KIND_TRACK = "track"            # a radar track of a recording
KIND_OBJECT = "object"          # a labelled object of a data set (positive)
KIND_BACKGROUND = "background"  # same size, same rows, no labelled object (negative)
# A background ROI whose column holds lidar points standing above the ground at or
# before its range: something unlabelled stands there (a hedge, a wall, a post).
KIND_BACKGROUND_STANDING = "background_standing"
KIND_LIDAR = "lidar"            # lidar structure on no labelled object (negative)
KIND_RADAR = "radar"            # radar returns on no labelled object (negative)


class FrameRef(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """How to rebuild the grey frame of a record (tools/eval/frames.py).

    kind "mcap": the CompressedFrame logged at `log_time_ns` on `topic` of `path`.
    kind "image": the image file `path`, resized by `scale` (INTER_AREA) and, with
    `jpeg_quality` > 0, JPEG-coded and decoded as the camera would. A ROI file stores
    `path` absolute; a relative one (a file written by hand) is relative to the ROI file.
    """

    kind: str
    path: str
    topic: str = ""
    log_time_ns: int = 0
    seq: int = -1
    scale: float = 1.0
    jpeg_quality: int = 0


class Score(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """One verifier on one ROI: `score` None when not applicable (it needs depth the data
    does not have); `us` the time verify() took; `score_name` what the score is
    (e.g. "edge_density"; "" in sets written before verifiers said); `cannot_tell` the
    verifier said it could not tell (GateResult.unverifiable; `verified` is then False,
    and fusion's decision, not the check, settles what happens)."""

    score: float | None
    verified: bool | None
    us: float = 0.0
    score_name: str = ""        # what the score is, as the verifier says (GateResult)
    cannot_tell: bool = False


class RoiRecord(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    id: str
    source: str                         # recording | kitti | vod
    session: str                        # recording file or data-set split
    frame: str                          # frame id within the session
    t_ns: int                           # radar cycle (recordings) or 0
    camera: str
    image_w: int
    image_h: int
    roi: tuple[int, int, int, int]      # x, y, w, h in the verifiers' image
    column: tuple[int, int, int, int]
    range_m: float
    kind: str
    frame_ref: FrameRef
    ttc_s: float | None = None          # range / closing speed; None when not closing
    track_id: int = -1
    obj_class: str = ""
    truth: str | None = None            # YES / NO from ground truth; None: label it
    density: float = 0.0                # the paper's gate score (edge density)
    lighting: str = ""                  # day | dusk | night (frame median grey level)
    frame_median: float = 0.0
    has_depth: bool = False
    object_in_view: bool = False        # a negative with a labelled object in its column
    scores: dict[str, Score] = msgspec.field(default_factory=dict)
    frame_canny_us: float | None = None  # full-frame Canny, on one record per frame
    # The frame's content (tools/eval/frames.py: frame_digest): what held-out checks and
    # training folds go by, never the path. "" in sets written without it: computed then.
    frame_sha256: str = ""
    scenario: str = ""                  # the simulator's scenario (sim/world), else ""

    @property
    def frame_key(self) -> str:
        """The frame's name across sessions: `session:frame`."""
        return f"{self.session}:{self.frame}"

    @property
    def roi_area_pct(self) -> float:
        return 100.0 * self.roi[2] * self.roi[3] / (self.image_w * self.image_h)


class RunInfo(msgspec.Struct, forbid_unknown_fields=True):
    """What produced a ROI set."""

    sources: list[str]
    verifiers: dict[str, dict[str, float | int | str | bool]]
    settings: dict[str, object]
    counters: dict[str, int]
    errors: list[str]
    seconds: float
    workers: int
    scheduler: str
    machine: dict[str, object]


_encoder = msgspec.json.Encoder()
_decoder = msgspec.json.Decoder(RoiRecord)


class RecordFileError(ValueError):
    """A ROI file that cannot be read; the message names the file and line."""


def _frame_at(r: RoiRecord, base: Path) -> RoiRecord:
    """`r` with its frame's path absolute: a relative one taken from `base`."""
    ref = r.frame_ref
    if not ref.path or os.path.isabs(ref.path):
        return r
    return msgspec.structs.replace(r, frame_ref=msgspec.structs.replace(
        ref, path=os.path.abspath(base / ref.path)))


def write_records(path: Path, records: Iterable[RoiRecord]) -> int:
    """Write JSON lines, frame paths absolute (the file works from any directory);
    returns how many. Raises OSError."""
    n = 0
    path.parent.mkdir(parents=True, exist_ok=True)
    cwd = Path.cwd()
    with open(path, "wb") as f:
        for r in records:
            f.write(_encoder.encode(_frame_at(r, cwd)))
            f.write(b"\n")
            n += 1
    return n


def iter_records(path: Path) -> Iterator[RoiRecord]:
    """Raises RecordFileError naming the bad line, OSError when unreadable."""
    with open(path, "rb") as f:
        for i, line in enumerate(f, 1):
            if not line.strip():
                continue
            try:
                yield _frame_at(_decoder.decode(line), path.parent)
            except (msgspec.DecodeError, msgspec.ValidationError) as exc:
                raise RecordFileError(f"{path}:{i}: not a ROI record: {exc}") from exc


def read_records(path: str | Path) -> list[RoiRecord]:
    """A ROI file, or a folder holding rois.jsonl. Raises RecordFileError, OSError."""
    p = Path(path)
    if p.is_dir():
        p = p / ROIS_FILE
    return list(iter_records(p))


def write_run(path: Path, info: RunInfo) -> None:
    path.write_bytes(msgspec.json.format(msgspec.json.encode(info), indent=1))


SCORES_VERIFIER = "scores"


def records_from_scores(path: str | Path, tau: float) -> list[RoiRecord]:
    """ROI records from a CSV of scores (header `id,score`, optional columns `session`,
    `frame`, `kind`, `range_m`, `lighting`), scored as verifier "scores" that passes at
    score >= tau: for judging scores computed elsewhere with the same tables.

    Raises RecordFileError naming the bad line, OSError when unreadable.
    """
    import csv

    p = Path(path)
    out = []
    with open(p, newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        if reader.fieldnames is None or not {"id", "score"} <= set(reader.fieldnames):
            raise RecordFileError(f"{p}: expected a header with at least id,score")
        for i, row in enumerate(reader, 2):
            try:
                score = float(row["score"])
                range_m = float(row.get("range_m") or 0.0)
            except ValueError as exc:
                raise RecordFileError(f"{p}:{i}: {exc}") from exc
            session = row.get("session") or "scores"
            out.append(RoiRecord(
                id=row["id"], source="scores", session=session,
                frame=row.get("frame") or row["id"], t_ns=0, camera="", image_w=1,
                image_h=1, roi=(0, 0, 1, 1), column=(0, 0, 1, 1), range_m=range_m,
                kind=row.get("kind") or KIND_TRACK, frame_ref=FrameRef("none", ""),
                lighting=row.get("lighting") or "",
                scores={SCORES_VERIFIER: Score(score, score >= tau)}))
    return out
