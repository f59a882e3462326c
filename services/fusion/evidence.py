"""Evidence over time, per track (pure): the sum of a verifier's per-frame
log-likelihood ratios, clipped to [floor, ceiling] (common/config/fusion.py,
EvidenceSettings, says what each field does).

A radar false target persists frame after frame at the same place, and so does the
evidence against it; a real obstacle's evidence grows as it comes closer. Summing lets
neither one frame of road texture brake for a ghost nor one frame whose depth misses a
thin bicycle veto it.
"""

from common.config.fusion import EvidenceSettings

LLR_KEY = "llr"                 # a verifier's per-frame value, in its GateResult.detail
EVIDENCE_KEY = "evidence_llr"   # the track's sum after this frame, in gate_detail


class TrackEvidence:
    """Per-track sums, keyed by track id, forgotten `forget_s` after a track's last
    frame."""

    def __init__(self, s: EvidenceSettings) -> None:
        self.s = s
        self._forget_ns = round(s.forget_s * 1e9)
        self._sums: dict[int, tuple[float, int]] = {}     # id -> (sum, last stamp ns)

    def add(self, track_id: int, llr: float, stamp_ns: int) -> float:
        """The track's sum after this frame's `llr` (a non-finite llr counts as 0)."""
        total, last = self._sums.get(track_id, (0.0, stamp_ns))
        if stamp_ns - last > self._forget_ns:
            total = 0.0
        if llr == llr and abs(llr) != float("inf"):
            total = min(max(total + llr, self.s.floor), self.s.ceiling)
        self._sums[track_id] = (total, stamp_ns)
        return total

    def vetoed(self, total: float) -> bool:
        return total <= self.s.veto_at

    def forget_older(self, stamp_ns: int) -> None:
        """Drop the tracks last checked more than `forget_s` before `stamp_ns`."""
        if self._sums:
            old = [k for k, (_, t) in self._sums.items() if stamp_ns - t > self._forget_ns]
            for k in old:
                del self._sums[k]

    def __len__(self) -> int:
        return len(self._sums)
