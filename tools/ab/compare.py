"""Compare two fusion instances cycle by cycle, pure.

Both instances run on the same radar cycles, so their outputs pair up by radar sequence
number (VerifiedTargets by sensor and radar_seq, BrakeCommand by radar_seq). For every
cycle both published, the comparison (the re-run's, tools/recording/compare.py, on
`COMMAND_FIELDS` and `TRACK_FIELDS`) finds where they disagreed: the command's
decision, and per track the verification and decision (reported with both densities,
to see how far apart the verifiers were). Consecutive disagreeing cycles of the same
kind are grouped into episodes. Cycles only one instance published are counted, not
compared.
"""

from collections import Counter
from dataclasses import dataclass, field

from aeb_radar_camera.common.messages import BrakeCommand, VerifiedTarget, VerifiedTargets
from aeb_radar_camera.tools.recording.compare import Comparison

PENDING_CYCLES = 50    # a cycle still unpaired after this many newer ones is unmatched
COMMAND_FIELDS = ("decision",)
TRACK_FIELDS = ("verification", "decision")


@dataclass(frozen=True)
class Disagreement:
    radar_seq: int
    what: str                 # "command", "track"
    track_id: int             # -1 for the command
    primary: str              # e.g. "BRAKE", "verified/BRAKE"
    candidate: str
    detail: str               # ranges, densities, reasons

    @property
    def kind(self) -> str:
        return f"{self.what}: {self.primary} vs {self.candidate}"


@dataclass
class Episode:
    kind: str
    track_id: int
    first_seq: int
    last_seq: int
    cycles: int
    example: str


@dataclass
class Report:
    primary: str
    candidate: str
    cycles_compared: int = 0
    commands_compared: int = 0
    commands_disagreed: int = 0
    tracks_compared: int = 0
    tracks_disagreed: int = 0
    only_primary: int = 0          # cycles only the primary published (targets)
    only_candidate: int = 0
    tracks_only_in_one: int = 0
    kinds: Counter[str] = field(default_factory=Counter)
    verification: Counter[tuple[str, str]] = field(default_factory=Counter)
    episodes: list[Episode] = field(default_factory=list)


def _track_label(t: VerifiedTarget) -> str:
    return f"{t.verification.value}/{t.decision.value}"


def _density(t: VerifiedTarget) -> str:
    return "-" if t.density is None else f"{t.density:.3f}"


class Comparator:
    """Feed it both instances' messages in any order; read `report()` at the end."""

    def __init__(self, primary: str = "primary", candidate: str = "candidate") -> None:
        if primary == candidate:
            raise ValueError("primary and candidate must be different instances")
        self.primary = primary
        self.candidate = candidate
        self._targets: dict[str, dict[tuple[str, int], VerifiedTargets]] = {
            primary: {}, candidate: {}}
        self._commands: dict[str, dict[int, BrakeCommand]] = {primary: {}, candidate: {}}
        self._report = Report(primary, candidate)
        self._open: dict[tuple[str, int], Episode] = {}
        self._newest = -1
        self._comparison = Comparison(command_fields=COMMAND_FIELDS, cycle_fields=(),
                                      track_fields=TRACK_FIELDS, keep_differences=False)

    def add_targets(self, msg: VerifiedTargets) -> None:
        if msg.instance not in self._targets:
            return
        key = (msg.radar_sensor, msg.radar_seq)
        other = self.candidate if msg.instance == self.primary else self.primary
        mine = self._targets[msg.instance]
        theirs = self._targets[other]
        if key in theirs:
            pair = (msg, theirs.pop(key)) if msg.instance == self.primary else (
                theirs.pop(key), msg)
            self._compare_targets(*pair)
        else:
            mine[key] = msg
        self._expire(msg.radar_seq)

    def add_command(self, msg: BrakeCommand) -> None:
        if msg.instance not in self._commands:
            return
        other = self.candidate if msg.instance == self.primary else self.primary
        theirs = self._commands[other]
        if msg.radar_seq in theirs:
            p, c = ((msg, theirs.pop(msg.radar_seq)) if msg.instance == self.primary
                    else (theirs.pop(msg.radar_seq), msg))
            self._compare_commands(p, c)
        else:
            self._commands[msg.instance][msg.radar_seq] = msg
        self._expire(msg.radar_seq)

    def _expire(self, seq: int) -> None:
        self._newest = max(self._newest, seq)
        edge = self._newest - PENDING_CYCLES
        for inst, pending in self._targets.items():
            for key in [k for k in pending if k[1] < edge]:
                del pending[key]
                if inst == self.primary:
                    self._report.only_primary += 1
                else:
                    self._report.only_candidate += 1
        for pending_cmd in self._commands.values():
            for seq_ in [s for s in pending_cmd if s < edge]:
                del pending_cmd[seq_]

    def _note(self, diff: Disagreement | None, seq: int, kind_key: tuple[str, int]) -> None:
        """Extend or close the episode of `kind_key` (what, track) at cycle `seq`."""
        episode = self._open.get(kind_key)
        if diff is None:
            if episode is not None:
                del self._open[kind_key]
            return
        self._report.kinds[diff.kind] += 1
        if episode is not None and episode.kind == diff.kind and seq - episode.last_seq <= 2:
            episode.last_seq = seq
            episode.cycles += 1
            return
        episode = Episode(diff.kind, diff.track_id, seq, seq, 1, diff.detail)
        self._open[kind_key] = episode
        self._report.episodes.append(episode)

    def _compare_commands(self, p: BrakeCommand, c: BrakeCommand) -> None:
        r = self._report
        r.commands_compared += 1
        diff = None
        if self._comparison.add_command(p.radar_seq, p.header.stamp_ns, p, c):
            r.commands_disagreed += 1
            diff = Disagreement(p.radar_seq, "command", -1, p.decision.value,
                                c.decision.value, f"primary: {p.reason} | candidate: {c.reason}")
        self._note(diff, p.radar_seq, ("command", -1))

    def _compare_targets(self, p: VerifiedTargets, c: VerifiedTargets) -> None:
        r = self._report
        r.cycles_compared += 1
        found = self._comparison.add_targets(p.radar_seq, p.header.stamp_ns, p, c)
        r.tracks_only_in_one += sum(d.field == "present" for d in found)
        differing = {d.track_id for d in found if d.field != "present"}
        ps = {t.track_id: t for t in p.targets}
        cs = {t.track_id: t for t in c.targets}
        for tid in sorted(ps.keys() & cs.keys()):
            tp, tc = ps[tid], cs[tid]
            r.tracks_compared += 1
            r.verification[(tp.verification.value, tc.verification.value)] += 1
            diff = None
            if tid in differing:
                r.tracks_disagreed += 1
                diff = Disagreement(p.radar_seq, "track", tid, _track_label(tp),
                                    _track_label(tc),
                                    f"track {tid} at {tp.range_m:.1f} m, y {tp.y_m:+.1f} m: "
                                    f"density {_density(tp)} ({p.verifier}) vs "
                                    f"{_density(tc)} ({c.verifier})")
            self._note(diff, p.radar_seq, ("track", tid))

    def report(self) -> Report:
        return self._report


def render(report: Report, max_episodes: int = 20) -> str:
    r = report
    lines = [f"A/B: {r.primary} (followed by the brake) vs {r.candidate} (shadow)",
             f"radar cycles compared: {r.cycles_compared} (targets), {r.commands_compared} "
             f"(commands); unpaired cycles: {r.only_primary} only {r.primary}, "
             f"{r.only_candidate} only {r.candidate}"]
    if r.commands_compared:
        pct = 100.0 * (r.commands_compared - r.commands_disagreed) / r.commands_compared
        lines.append(f"commands: {r.commands_disagreed} disagreed ({pct:.1f}% agreement)")
    if r.tracks_compared:
        pct = 100.0 * (r.tracks_compared - r.tracks_disagreed) / r.tracks_compared
        lines.append(f"track verdicts: {r.tracks_disagreed} of {r.tracks_compared} disagreed "
                     f"({pct:.1f}% agreement); {r.tracks_only_in_one} tracks seen by one only")
    if r.verification:
        lines.append(f"verification ({r.primary} -> {r.candidate}):")
        for (a, b), n in sorted(r.verification.items(), key=lambda kv: -kv[1]):
            lines.append(f"  {a:>12} -> {b:<12} {n}")
    if r.kinds:
        lines.append("disagreements by kind (cycles):")
        for kind, n in r.kinds.most_common():
            lines.append(f"  {n:>6}  {kind}")
    if r.episodes:
        lines.append(f"episodes (consecutive cycles), first {min(max_episodes, len(r.episodes))}"
                     f" of {len(r.episodes)}:")
        for e in r.episodes[:max_episodes]:
            lines.append(f"  radar #{e.first_seq}-#{e.last_seq} ({e.cycles} cycles) {e.kind}: "
                         f"{e.example}")
    else:
        lines.append("no disagreement")
    return "\n".join(lines)
