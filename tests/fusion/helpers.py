"""Builders for fusion tests: tracks, cycles, frames, cores."""

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.config.fusion import FusionConfig, FusionSettings
from aeb_radar_camera.common.config.loader import parse_config
from aeb_radar_camera.common.messages import (
    Decision,
    Header,
    OutputMode,
    RadarTrack,
    RadarTracks,
    VerifiedTarget,
)
from aeb_radar_camera.common.resources import EXAMPLE_CALIBRATION
from aeb_radar_camera.services.fusion.core import FusionCore
from aeb_radar_camera.services.fusion.frames import DecodedFrame, FrameFeed
from aeb_radar_camera.services.fusion.roi import ColumnGeometry, ColumnProjector, Roi
from aeb_radar_camera.services.fusion.verifiers import GateResult, Observation, ParamValue, create

CALIBRATION = str(EXAMPLE_CALIBRATION)
T0 = 1_800_000_000_000_000_000      # a wall-clock instant (ns)
MS = 1_000_000
CAL = Calibration.load(CALIBRATION)


def track(tid: int = 1, x: float = 10.0, y: float = 0.0, vx: float = -5.0, vy: float = 0.0,
          confirmed: bool = True, range_rate: float | None = None) -> RadarTrack:
    r = math.hypot(x, y)
    rr = (x * vx + y * vy) / r if range_rate is None else range_rate
    return RadarTrack(track_id=tid, x_m=x, y_m=y, vx_mps=vx, vy_mps=vy, range_m=r,
                      range_rate_mps=rr, rcs_dbsm=5.0, confirmed=confirmed, hits=5, misses=0,
                      x_var_m2=0.1, y_var_m2=0.1)


def cycle(*tracks: RadarTrack, seq: int = 0, stamp_ns: int = T0,
          last_frame_mono_ns: int = 42) -> RadarTracks:
    return RadarTracks(header=Header(seq=seq, source="radar/front", stamp_ns=stamp_ns,
                                     pub_mono_ns=0),
                       sensor="front", mode=OutputMode.OBJECTS, meas_counter=seq,
                       complete=True, n_detections=len(tracks), n_prefiltered=len(tracks),
                       last_frame_mono_ns=last_frame_mono_ns, processing_ns=1000,
                       tracks=tracks)


def frame(stamp_ns: int = T0, seq: int = 7, gray: np.ndarray | None = None,
          rx_mono_ns: int = 0) -> DecodedFrame:
    if gray is None:
        gray = np.full((CAL.height, CAL.width), 100, np.uint8)
    return DecodedFrame("front", seq, stamp_ns, rx_mono_ns, gray)


def feed(*frames: DecodedFrame, **kw: Any) -> FrameFeed:
    return FrameFeed(frames=frames, received=len(frames), **kw)


@dataclass
class FixedVerifier:
    """Answers a fixed verdict and records the ROIs it was asked about."""

    verdict: bool = True
    density: float = 0.1
    name: str = "fixed"
    needs_depth: bool = False
    calls: list[Roi] = field(default_factory=list)

    def params(self) -> dict[str, ParamValue]:
        return {"verdict": self.verdict}

    def verify(self, obs: Observation) -> GateResult:
        self.calls.append(obs.roi)
        return GateResult(self.density, self.verdict)


def observe(gray: np.ndarray, roi: Roi, range_m: float = 10.0) -> Observation:
    """An observation of a ROI whose column is the ROI itself."""
    return Observation(gray, roi, roi, range_m)


def settings(**fusion: Any) -> FusionSettings:
    """Fusion settings from a nested dict like the TOML's [fusion] table."""
    return parse_config({"fusion": fusion}, FusionConfig).fusion


def make_core(fixed: Any = None, **fusion: Any) -> FusionCore:
    """A core with `fixed` as its verifier; without one, the registry's verifier when the
    settings name one, else a FixedVerifier that verifies everything."""
    s = settings(**fusion)
    geometry = ColumnGeometry(s.roi.column_height_m, s.roi.column_half_width_m,
                              s.roi.padding_px)
    if fixed is None:
        fixed = (create(s.verifier.name, s.verifier.params) if "verifier" in fusion
                 else FixedVerifier())
    return FusionCore(s, ColumnProjector(CAL, geometry), fixed)


def run(core: FusionCore, *tracks: RadarTrack, frames: FrameFeed | None = None,
        stamp_ns: int = T0, now_ns: int | None = None, seq: int = 0):
    """One cycle with a fresh frame at the radar stamp unless `frames` is given."""
    f = feed(frame(stamp_ns)) if frames is None else frames
    now = stamp_ns + 5 * MS if now_ns is None else now_ns
    return core.process(cycle(*tracks, seq=seq, stamp_ns=stamp_ns), f, now, 1)


def most_severe(targets: tuple[VerifiedTarget, ...]) -> tuple[Decision, int]:
    """(decision, track) the command must carry, by the plain definition: the most severe
    target decision, ties to the smallest TTC_eff, first in order; (NONE, -1) if none."""
    rank = {Decision.NONE: 0, Decision.WARNING: 1, Decision.BRAKE: 2}
    best = None
    for tgt in targets:
        if tgt.decision is Decision.NONE:
            continue
        key = (rank[tgt.decision], -(tgt.ttc_eff_s or 0.0))
        if best is None or key > best[0]:
            best = (key, tgt)
    return (Decision.NONE, -1) if best is None else (best[1].decision, best[1].track_id)
