"""The edge-density verifiers.

- `edge_density`: the paper's gate. Canny(40, 120) on the ROI, d = edges / pixels,
  verified iff d >= tau (0.025).
- `adaptive_edge_density`: the same gate made robust to night scenes, the paper's weak
  point (precision 0.27 in the evening, from street lights and sensor noise). Canny
  thresholds rise with the ROI's measured noise; in a dark ROI, edges around small
  saturated blobs (lamps, headlights, reflections) are not counted and the density is
  compared with its own threshold. On a lit ROI with little noise it equals
  `edge_density` exactly.
"""

import math
from collections.abc import Mapping
from typing import Annotated

import cv2
import msgspec
import numpy as np

from aeb_radar_camera.services.fusion.verifiers.base import (
    Fraction,
    GateResult,
    Observation,
    ParamValue,
    Threshold,
    Verifier,
    parse_params,
)

SCORE = "edge_density"


def _check_thresholds(low: float, high: float) -> None:
    if low > high:
        raise ValueError("low must not exceed high")


class EdgeDensityParams(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    low: Threshold = 40.0
    high: Threshold = 120.0
    tau: Fraction = 0.025

    def __post_init__(self) -> None:
        _check_thresholds(self.low, self.high)


class EdgeDensity:
    """The paper's gate, on a slice of the frame (no copy)."""

    name = "edge_density"
    needs_depth = False

    def __init__(self, p: EdgeDensityParams) -> None:
        self.p = p

    def params(self) -> dict[str, ParamValue]:
        return msgspec.structs.asdict(self.p)

    def verify(self, obs: Observation) -> GateResult:
        roi = obs.roi
        patch = obs.gray[roi.y:roi.y + roi.h, roi.x:roi.x + roi.w]
        density = cv2.countNonZero(cv2.Canny(patch, self.p.low, self.p.high)) / roi.area
        return GateResult(density, density >= self.p.tau, score_name=SCORE)


def make_edge_density(params: Mapping[str, ParamValue]) -> Verifier:
    return EdgeDensity(parse_params(params, EdgeDensityParams, "edge_density"))


class AdaptiveEdgeDensityParams(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    low: Threshold = 40.0           # floor of the low Canny threshold (the paper's value)
    high: Threshold = 120.0         # floor of the high threshold
    tau: Fraction = 0.025           # threshold on the density of a lit ROI (the paper's)
    # Low threshold = max(low, noise_k * sigma), sigma the ROI's noise in grey levels;
    # high keeps the paper's high/low ratio. Noise edges are what a dark, high-gain
    # image is made of.
    noise_k: Annotated[float, msgspec.Meta(ge=0, le=100)] = 12.0
    # A ROI is dark when its median grey level is at most dark_median. In a dark ROI,
    # edges within highlight_px of a saturated pixel (>= saturation) are not counted (a
    # lamp is a few saturated pixels on a dark background; by day a saturated area is more
    # likely a sunlit white object whose edges must count), and the density is compared
    # with tau_dark: with raised thresholds and masked lights, an obstacle lit by the
    # headlights keeps fewer edges than by day.
    dark_median: Annotated[int, msgspec.Meta(ge=0, le=255)] = 70
    tau_dark: Fraction = 0.0175
    saturation: Annotated[int, msgspec.Meta(ge=1, le=255)] = 235
    highlight_px: Annotated[int, msgspec.Meta(ge=0, le=50)] = 4
    # A saturated blob larger than this share of the ROI is an object (a white box in the
    # headlights, a lit truck), not a lamp: it is never masked.
    max_light: Fraction = 0.05

    def __post_init__(self) -> None:
        _check_thresholds(self.low, self.high)


# |I(x+1) - I(x)| of Gaussian noise with deviation s has median 0.6745 * sqrt(2) * s.
_MAD_TO_SIGMA = 1.0 / (0.6745 * math.sqrt(2.0))


def _median_u8(values: np.ndarray) -> float:
    """Median of a uint8 image, from its histogram."""
    hist = cv2.calcHist([values], [0], None, [256], [0, 256]).ravel()
    return float(np.searchsorted(np.cumsum(hist), values.size / 2.0))


class AdaptiveEdgeDensity:
    """Edge density with noise-adapted Canny thresholds and highlight masking."""

    name = "adaptive_edge_density"
    needs_depth = False

    def __init__(self, p: AdaptiveEdgeDensityParams) -> None:
        self.p = p
        self._ratio = p.high / p.low if p.low > 0 else 3.0
        r = p.highlight_px
        self._kernel = (cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
                        if r > 0 else None)

    def params(self) -> dict[str, ParamValue]:
        return msgspec.structs.asdict(self.p)

    def noise_sigma(self, patch: np.ndarray) -> float:
        """Noise deviation from the median horizontal difference: object edges are few
        pixels of a ROI, so they barely move the median."""
        diff = cv2.absdiff(patch[:, 1:], patch[:, :-1])
        return _median_u8(diff) * _MAD_TO_SIGMA

    def _lights(self, patch: np.ndarray, area: int) -> np.ndarray | None:
        """Mask (255) of the small saturated blobs and their rims, or None if none."""
        sat = cv2.threshold(patch, self.p.saturation - 1, 255, cv2.THRESH_BINARY)[1]
        n, labels, stats, _ = cv2.connectedComponentsWithStats(sat, connectivity=8)
        small = np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] <= self.p.max_light * area) + 1
        if len(small) == 0:
            return None
        if len(small) < n - 1:
            sat = np.where(np.isin(labels, small), np.uint8(255), np.uint8(0))
        return cv2.dilate(sat, self._kernel) if self._kernel is not None else sat

    def verify(self, obs: Observation) -> GateResult:
        p, roi = self.p, obs.roi
        patch = obs.gray[roi.y:roi.y + roi.h, roi.x:roi.x + roi.w]
        sigma = self.noise_sigma(patch) if roi.w > 1 else 0.0
        low = max(p.low, p.noise_k * sigma)
        high = max(p.high, low * self._ratio)
        edges = cv2.Canny(patch, low, high)
        n_edges = cv2.countNonZero(edges)
        pixels = roi.area
        # One histogram of the ROI answers both "is it dark?" and "anything saturated?".
        cum = np.cumsum(cv2.calcHist([patch], [0], None, [256], [0, 256]).ravel())
        dark = float(np.searchsorted(cum, pixels / 2.0)) <= p.dark_median
        masked_frac = 0.0
        if dark and cum[-1] > cum[p.saturation - 1]:
            mask = self._lights(patch, roi.area)
            if mask is not None:
                n_masked = cv2.countNonZero(mask)
                n_edges -= cv2.countNonZero(cv2.bitwise_and(edges, mask))
                pixels -= n_masked
                masked_frac = n_masked / roi.area
        density = n_edges / pixels if pixels > 0 else 0.0
        tau = p.tau_dark if dark else p.tau
        return GateResult(density, density >= tau,
                          {"low": low, "high": high, "noise": sigma, "masked": masked_frac,
                           "dark": float(dark), "tau": tau}, SCORE)


def make_adaptive(params: Mapping[str, ParamValue]) -> Verifier:
    return AdaptiveEdgeDensity(
        parse_params(params, AdaptiveEdgeDensityParams, "adaptive_edge_density"))
