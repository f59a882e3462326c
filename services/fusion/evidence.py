"""Evidence over time, per track (pure): the sum of a verifier's per-frame
log-likelihood ratios, clipped to [floor, ceiling] (common/config/fusion.py,
EvidenceSettings, says what each field does).

A radar false target persists frame after frame at the same place, and so does the
evidence against it; a real obstacle's evidence grows as it comes closer. Summing lets
neither one frame of road texture brake for a ghost nor one frame whose depth misses a
thin bicycle veto it.
"""

import math

from aeb_radar_camera.common.config.fusion import EvidenceSettings

LLR_KEY = "llr"                 # a verifier's per-frame value, in its GateResult.detail
EVIDENCE_KEY = "evidence_llr"   # the track's sum after this frame, in gate_detail
EVIDENCE_CARRIED_KEY = "evidence_carried"   # 1: no frame showed the track, the sum carried
# In gate_detail: the verifier could not tell this frame and the track's evidence holds
# no confirmation (`[fusion.decision.kinematic] cannot_tell_full_only` then applies).
CANNOT_TELL_KEY = "cannot_tell"
# In gate_detail: the camera's appearance model vetoed this frame's confirmation.
APPEARANCE_VETO = "appearance_veto"
# In gate_detail, where depth confirms: where the pixels at the range stand sideways and
# where the window lies at the range (ground y, metres, left positive), and whether the
# window's columns beyond the at-pixels on the low-y / high-y side see through (1 / 0).
AT_Y_MIN, AT_Y_MAX = "at_y_min_m", "at_y_max_m"
WINDOW_Y_MIN, WINDOW_Y_MAX = "window_y_min_m", "window_y_max_m"
THROUGH_LOW_Y, THROUGH_HIGH_Y = "through_low_y", "through_high_y"
# In gate_detail: the share of the check's window within the image's columns.
IN_VIEW = "in_view"
# In gate_detail: the camera showed the track's object beside the path (decision NONE).
BESIDE_PATH = "beside_path_camera"
# In gate_detail: the camera put a track the point test leaves out of the path in it.
INTO_PATH = "into_path_camera"
# In gate_detail: the track is out of the path as the road's edge (a chain of stationary
# returns along a bend, services/fusion/road_edge.py).
ROAD_EDGE = "road_edge"


class TrackEvidence:
    """Per-track sums, keyed by track id, forgotten `forget_s` after a track's last
    frame."""

    def __init__(self, s: EvidenceSettings) -> None:
        self.s = s
        self._forget_ns = round(s.forget_s * 1e9)
        self._handover_ns = round(s.handover_s * 1e9)
        # id -> (sum, last stamp ns, x, y at that frame)
        self._sums: dict[int, tuple[float, int, float, float]] = {}

    def add(self, track_id: int, llr: float, stamp_ns: int, xy: tuple[float, float] = (
            math.nan, math.nan)) -> float:
        """The track's sum after this frame's `llr` (a non-finite llr counts as 0)."""
        total, last, _, _ = self._sums.get(track_id, (0.0, stamp_ns, 0.0, 0.0))
        if stamp_ns - last > self._forget_ns:
            total = 0.0
        if math.isfinite(llr):
            total = min(max(total + llr, self.s.floor), self.s.ceiling)
        self._sums[track_id] = (total, stamp_ns, xy[0], xy[1])
        return total

    def carried(self, track_id: int, xy: tuple[float, float], stamp_ns: int
                ) -> float | None:
        """The evidence that stands for a track no frame shows now: its own sum, or, for a
        track the radar has just (re)started there, the sum of the track checked last
        within `handover_m` of it in the last `handover_s`, which it then keeps; None when
        there is none."""
        own = self._sums.get(track_id)
        if own is not None and stamp_ns - own[1] <= self._forget_ns:
            return own[0]
        best: tuple[int, float] | None = None
        for total, last, x, y in self._sums.values():
            near = (stamp_ns - last <= self._handover_ns
                    and math.hypot(x - xy[0], y - xy[1]) <= self.s.handover_m)
            if near and (best is None or last > best[0]):
                best = (last, total)
        if best is None:
            return None
        # The new track keeps it (as old as it is) for the cycles it stays out of view.
        self._sums[track_id] = (best[1], best[0], *xy)
        return best[1]

    def vetoed(self, total: float) -> bool:
        return total <= self.s.veto_at

    def forget_older(self, stamp_ns: int) -> None:
        """Drop the tracks last checked more than `forget_s` before `stamp_ns`."""
        if self._sums:
            old = [k for k, (_, t, _, _) in self._sums.items()
                   if stamp_ns - t > self._forget_ns]
            for k in old:
                del self._sums[k]

    def __len__(self) -> int:
        return len(self._sums)
