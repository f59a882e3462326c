"""Every verifier of fusion's registry on the same observations, timed.

A verifier is named by its registry name and parameters: `edge_density` (defaults) or
`edge_density:tau=0.08,low=30`. Verifiers that need depth score None (not applicable)
where the data has none.
"""

import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.services.fusion.roi import Roi
from aeb_radar_camera.services.fusion.verifiers import (
    Observation,
    ParamValue,
    Verifier,
    VerifierConfigError,
    available,
    create,
)
from aeb_radar_camera.tools.eval.records import Score

PAPER_GATE = "edge_density"
# The lighting estimate of a frame from its grey levels: night when half the frame is
# darker than NIGHT_MEDIAN; dusk when even its brightest tenth (sky, lit surfaces) stays
# below DUSK_P90; day otherwise. Daylight frames (KITTI: p90 181-255) and the simulator's
# day, dusk and night looks (p90 214, 64; median 20-24) fall on the intended sides.
NIGHT_MEDIAN = 30.0
DUSK_P90 = 120.0


@dataclass(frozen=True)
class VerifierSpec:
    label: str                  # how tables name it: the name, or name:params
    name: str
    params: dict[str, ParamValue] = field(default_factory=dict)


def _value(text: str) -> ParamValue:
    low = text.lower()
    if low in ("true", "false"):
        return low == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def parse_spec(text: str) -> VerifierSpec:
    """`name` or `name:key=value,key=value`. Raises VerifierConfigError (unknown name,
    bad parameter)."""
    name, _, rest = text.partition(":")
    params: dict[str, ParamValue] = {}
    for item in filter(None, (p.strip() for p in rest.split(","))):
        key, eq, value = item.partition("=")
        if not eq:
            raise VerifierConfigError(f"verifier {text!r}: expected key=value, got {item!r}")
        params[key.strip()] = _value(value.strip())
    create(name.strip(), params)                 # validates name and parameters now
    return VerifierSpec(text.strip(), name.strip(), params)


def default_specs(left_out: dict[str, str] | None = None) -> list[VerifierSpec]:
    """Every registered verifier that works with its default parameters (`hog_linear`
    and `combined` need a weights file: name them with --verifier); the others go into
    `left_out` (name -> why) when given."""
    out = []
    for name in available():
        try:
            create(name)
        except VerifierConfigError as exc:
            if left_out is not None:
                left_out[name] = str(exc)
            continue
        out.append(VerifierSpec(name, name))
    return out


class Scorer:
    """The verifiers of `specs`, built once per process."""

    def __init__(self, specs: list[VerifierSpec]) -> None:
        self.specs = specs
        self.verifiers: list[tuple[str, Verifier]] = [(s.label, create(s.name, s.params))
                                                      for s in specs]
        self._gate = create(PAPER_GATE)

    def prepare(self, calibration: Calibration) -> None:
        """Let verifiers precompute for this calibration (outside the timed verify)."""
        for _, v in self.verifiers:
            prepare = getattr(v, "prepare", None)
            if callable(prepare):
                prepare(calibration)

    def params(self) -> dict[str, dict[str, ParamValue]]:
        return {label: v.params() for label, v in self.verifiers}

    def score(self, obs: Observation) -> dict[str, Score]:
        out = {}
        for label, v in self.verifiers:
            if v.needs_depth and obs.depth_m is None:
                out[label] = Score(None, None)
                continue
            t0 = time.perf_counter_ns()
            result = v.verify(obs)
            us = (time.perf_counter_ns() - t0) / 1000.0
            out[label] = Score(float(result.score), bool(result.verified), us,
                               result.score_name, bool(result.unverifiable))
        return out

    def density(self, obs: Observation, scores: dict[str, Score]) -> float:
        """The paper's gate score of this ROI (its default parameters)."""
        s = scores.get(PAPER_GATE)
        if s is not None and s.score is not None:
            return s.score
        return float(self._gate.verify(obs).score)

    def full_frame_us(self, gray: np.ndarray) -> float:
        """The paper's gate on the whole frame (Table II's full-frame case)."""
        h, w = gray.shape
        obs = Observation(gray, Roi(0, 0, w, h), Roi(0, 0, w, h), 0.0)
        t0 = time.perf_counter_ns()
        self._gate.verify(obs)
        return (time.perf_counter_ns() - t0) / 1000.0


def lighting(gray: np.ndarray) -> tuple[str, float]:
    """(day | dusk | night, the frame's median grey level); see DUSK_P90. Every 4th pixel
    of every 4th row is plenty for a histogram and costs a sixteenth."""
    sample = np.ascontiguousarray(gray[::4, ::4])
    cum = np.cumsum(cv2.calcHist([sample], [0], None, [256], [0, 256]).ravel())
    median = float(np.searchsorted(cum, sample.size * 0.5))
    p90 = float(np.searchsorted(cum, sample.size * 0.9))
    if median < NIGHT_MEDIAN:
        return "night", median
    return ("dusk" if p90 < DUSK_P90 else "day"), median
