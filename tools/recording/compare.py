"""Two fusion outputs of the same radar cycles, cycle by cycle (pure): a re-run's against
the recorded ones (`aeb rerun --compare`), and a candidate instance's against the
primary's (`aeb ab-report`, which compares only the decisions and verifications).

Cycles pair up by the radar cycle (sequence number and stamp). Compared: every field of
the command but its header, the cycle's verifier and camera status, and every field of
every track's target; a track present on one side only is a difference too. Not
compared: what the live shell measured or counted (headers, `processing_ns`, the frame
counters), `radar_age_ms` (an input of the re-run), and the verifier's name and
parameters (a configuration, not a behaviour: reported once, beside the table).

Numbers are compared to rounding (relative 1e-6) unless the comparison is exact: a
change in the last bits of a float (a matrix product summed in another order, OpenCV's
float32 image features from another CPU's SIMD code) is not a change of behaviour;
`aeb rerun --exact` compares bit for bit.

Differences are grouped for the summary: commands, decisions (a track's decision),
densities (its verification and density), tracks (everything else of a track: position,
ROI, TTC, reasons, presence) and cycles (the verifier's status).
"""

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import msgspec

from aeb_radar_camera.common.messages import (
    BrakeCommand,
    RadarTrack,
    RadarTracks,
    VerifiedTarget,
    VerifiedTargets,
)

COMMAND_FIELDS = ("decision", "brake_level_pct", "verifier_status", "held", "track_id",
                  "range_m", "ttc_s", "reason")
CYCLE_FIELDS = ("verifier_status", "unavailable_reason", "camera", "cameras_unavailable")
TRACK_FIELDS = tuple(f for f in VerifiedTarget.__struct_fields__ if f != "track_id")
RADAR_CYCLE_FIELDS = ("mode", "meas_counter", "complete", "n_detections", "n_prefiltered",
                      "last_frame_mono_ns")
RADAR_TRACK_FIELDS = tuple(f for f in RadarTrack.__struct_fields__ if f != "track_id")
GROUPS = ("commands", "decisions", "densities", "tracks", "cycles")
REL_TOLERANCE = 1e-6


def _group(what: str, name: str) -> str:
    """Fusion's groups; a radar re-run has cycles and tracks only (its tracks carry no
    decision or density)."""
    if what == "command":
        return "commands"
    if what == "cycle":
        return "cycles"
    if name == "decision":
        return "decisions"
    if name in ("density", "verification", "gate_detail"):
        return "densities"
    return "tracks"


def _plain(value: Any) -> Any:
    """A field's value as JSON would have it (enums as their value, tuples as lists)."""
    return msgspec.to_builtins(value)


@dataclass(frozen=True)
class Difference:
    radar_seq: int
    stamp_ns: int
    what: str                  # "command", "cycle" or "track"
    track_id: int              # -1 unless a track
    field: str                 # "present" for a track on one side only
    recorded: Any
    rerun: Any

    @property
    def group(self) -> str:
        return _group(self.what, self.field)

    def key(self) -> tuple[int, int, str, int, str]:
        return (self.radar_seq, self.stamp_ns, self.what, self.track_id, self.field)

    def as_json(self) -> dict[str, Any]:
        return {"radar_seq": self.radar_seq, "stamp_ns": self.stamp_ns, "what": self.what,
                "track_id": self.track_id, "field": self.field,
                "recorded": self.recorded, "rerun": self.rerun}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> "Difference":
        return cls(d["radar_seq"], d["stamp_ns"], d["what"], d["track_id"], d["field"],
                   d["recorded"], d["rerun"])

    def text(self) -> str:
        who = "command" if self.what == "command" else (
            "cycle" if self.what == "cycle" else f"track {self.track_id}")
        return (f"radar #{self.radar_seq} {who} {self.field}: recorded {self.recorded!r}, "
                f"rerun {self.rerun!r}")


@dataclass
class Comparison:
    cycles: int = 0                  # cycles with recorded outputs to compare against
    cycles_differing: int = 0
    rerun_only: int = 0              # cycles re-run without a recorded output
    recorded_only: int = 0           # recorded outputs of cycles the re-run did not have
    compared: Counter[str] = field(default_factory=Counter)   # items per group
    differing: Counter[str] = field(default_factory=Counter)  # items differing per group
    fields: Counter[str] = field(default_factory=Counter)     # "group.field" -> count
    differences: list[Difference] = field(default_factory=list)
    verifiers: Counter[tuple[str, str]] = field(default_factory=Counter)  # (recorded, re-run)
    exact: bool = False              # floats bit for bit instead of to REL_TOLERANCE
    # what is compared (by default everything that is behaviour)
    command_fields: tuple[str, ...] = COMMAND_FIELDS
    cycle_fields: tuple[str, ...] = CYCLE_FIELDS
    track_fields: tuple[str, ...] = TRACK_FIELDS
    keep_differences: bool = True    # False: differences counted and returned, not kept

    def add(self, seq: int, stamp_ns: int, recorded_cmd: BrakeCommand | None,
            rerun_cmd: BrakeCommand, recorded: VerifiedTargets | None,
            rerun: VerifiedTargets) -> list[Difference]:
        """Compare one cycle (recorded outputs None: nothing to compare with)."""
        if recorded_cmd is None and recorded is None:
            self.rerun_only += 1
            return []
        self.cycles += 1
        found: list[Difference] = []
        if recorded_cmd is not None:
            found += self.add_command(seq, stamp_ns, recorded_cmd, rerun_cmd)
        if recorded is not None:
            found += self.add_targets(seq, stamp_ns, recorded, rerun)
        self.cycles_differing += bool(found)
        return found

    def add_command(self, seq: int, stamp_ns: int, a: BrakeCommand,
                    b: BrakeCommand) -> list[Difference]:
        """Compare the commands of one cycle (`a` recorded, `b` re-run)."""
        self.compared["commands"] += 1
        found = _fields(seq, stamp_ns, "command", -1, a, b, self.command_fields, self.exact)
        self.differing["commands"] += bool(found)
        return self._keep(found)

    def add_targets(self, seq: int, stamp_ns: int, a: VerifiedTargets,
                    b: VerifiedTargets) -> list[Difference]:
        """Compare the targets of one cycle (`a` recorded, `b` re-run)."""
        self.verifiers[(_verifier(a), _verifier(b))] += 1
        self.compared["cycles"] += 1
        cycle = _fields(seq, stamp_ns, "cycle", -1, a, b, self.cycle_fields, self.exact)
        self.differing["cycles"] += bool(cycle)
        return self._keep(cycle + self._tracks(seq, stamp_ns, a, b))

    def _keep(self, found: list[Difference]) -> list[Difference]:
        for d in found:
            self.fields[f"{d.group}.{d.field}"] += 1
        if self.keep_differences:
            self.differences += found
        return found

    def add_tracks(self, seq: int, stamp_ns: int, recorded: RadarTracks | None,
                   rerun: RadarTracks) -> list[Difference]:
        """Compare one radar cycle (recorded None: nothing to compare with)."""
        if recorded is None:
            self.rerun_only += 1
            return []
        self.cycles += 1
        self.compared["cycles"] += 1
        found = _fields(seq, stamp_ns, "cycle", -1, recorded, rerun, RADAR_CYCLE_FIELDS,
                        self.exact)
        self.differing["cycles"] += bool(found)
        a = {t.track_id: t for t in recorded.tracks}
        b = {t.track_id: t for t in rerun.tracks}
        for tid in sorted(a.keys() | b.keys()):
            self.compared["tracks"] += 1
            ta, tb = a.get(tid), b.get(tid)
            diffs = ([Difference(seq, stamp_ns, "track", tid, "present", ta is not None,
                                 tb is not None)] if ta is None or tb is None
                     else _fields(seq, stamp_ns, "track", tid, ta, tb, RADAR_TRACK_FIELDS,
                                   self.exact))
            self.differing["tracks"] += bool(diffs)
            found += diffs
        self.cycles_differing += bool(found)
        return self._keep(found)

    def _tracks(self, seq: int, stamp_ns: int, recorded: VerifiedTargets,
                rerun: VerifiedTargets) -> list[Difference]:
        a = {t.track_id: t for t in recorded.targets}
        b = {t.track_id: t for t in rerun.targets}
        found = []
        for tid in sorted(a.keys() | b.keys()):
            ta, tb = a.get(tid), b.get(tid)
            for g in ("decisions", "densities", "tracks"):
                self.compared[g] += 1
            if ta is None or tb is None:
                found.append(Difference(seq, stamp_ns, "track", tid, "present",
                                        ta is not None, tb is not None))
                self.differing["tracks"] += 1
                continue
            diffs = _fields(seq, stamp_ns, "track", tid, ta, tb, self.track_fields, self.exact)
            for g in ("decisions", "densities", "tracks"):
                self.differing[g] += any(d.group == g for d in diffs)
            found += diffs
        return found


def _verifier(t: VerifiedTargets) -> str:
    params = ", ".join(f"{k}={v}" for k, v in sorted(t.verifier_params.items()))
    return f"{t.verifier}({params})"


def _same(a: Any, b: Any) -> bool:
    """Equal, floats to REL_TOLERANCE (in lists and dicts too)."""
    if isinstance(a, float) and isinstance(b, float):
        return a == b or math.isclose(a, b, rel_tol=REL_TOLERANCE, abs_tol=1e-12)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(map(_same, a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return bool(a == b)


# Fields added to a message after recordings were made, with the value those recordings
# decode to: a recording that holds it made no statement, so it is not compared.
_ADDED_LATER = {"score_name": ""}


def _fields(seq: int, stamp_ns: int, what: str, track_id: int, a: Any, b: Any,
            names: tuple[str, ...], exact: bool) -> list[Difference]:
    out = []
    for name in names:
        va, vb = _plain(getattr(a, name)), _plain(getattr(b, name))
        if name in _ADDED_LATER and va == _ADDED_LATER[name]:
            continue
        if va != vb and (exact or not _same(va, vb)):
            out.append(Difference(seq, stamp_ns, what, track_id, name, va, vb))
    return out


def summary_table(c: Comparison) -> str:
    lines = [f"cycles compared: {c.cycles}, with a difference: {c.cycles_differing}"
             + (f"; re-run without a recorded output: {c.rerun_only}" if c.rerun_only else "")
             + (f"; recorded, not re-run: {c.recorded_only}" if c.recorded_only else ""),
             *(f"verifier: recorded {a}, re-run {b} ({n} cycles)"
               for (a, b), n in c.verifiers.items()),
             f"{'':<12} {'compared':>9} {'differ':>7}  fields"]
    for g in GROUPS:
        if not c.compared[g]:
            continue
        fields = ", ".join(f"{k.split('.', 1)[1]} {n}" for k, n in sorted(c.fields.items())
                           if k.startswith(g + "."))
        lines.append(f"{g:<12} {c.compared[g]:>9} {c.differing[g]:>7}  {fields}")
    return "\n".join(lines)


def check_declared(found: list[Difference], declared: list[Difference]
                   ) -> tuple[list[Difference], list[Difference]]:
    """(differences not declared, declared differences that did not happen): both empty
    when the re-run behaves exactly as declared."""
    want = {d.key(): d for d in declared}
    got = {d.key(): d for d in found}
    undeclared = [d for k, d in got.items() if k not in want or want[k] != d]
    missing = [d for k, d in want.items() if k not in got or got[k] != d]
    return undeclared, missing
