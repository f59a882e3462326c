"""The combined verifier: depth and appearance, one threshold, the deciding cue said.

Depth (`depth`) tells whether a surface stands in the column at the radar's range: it
rejects what the radar sees where nothing stands (metal on the road, a sign overhead, a
ghost) but confirms a wall, a guard rail or a tree that really is there. Appearance
(`hog_linear`, or `hog_people`) tells whether what stands there looks like an obstacle:
it rejects walls and vegetation. An obstacle must pass both.

Each cue is the registered verifier with its own parameters (`depth_tau`, `weights`
are passed through), and its score is taken relative to that verifier's own threshold:

    ratio = cue score / cue threshold       (hog_people: sigmoid(margin) / sigmoid(tau))
    score = min(depth ratio, 1) x appearance ratio,   verified iff score >= tau

Depth can only lower the score (capped at 1: a surface at the range says nothing of what
it is) and appearance must make up for a depth short of its threshold, so `tau` (default
1: both cues at their own thresholds) is the one number to set. On the KITTI sample this
product separates better than requiring both verdicts (docs/fusion.md): lidar depth
misses part of some objects, and a hard AND loses them. `detail` says which cue decided
(`decided_depth` or `decided_appearance` is 1: the one with the smaller ratio), both
ratios, and `depth_available` (0 when the camera has no depth for this frame: appearance
alone decides, and says so). Where depth finds nothing at the range (ratio 0) the score is
0 and appearance is not computed.
Edge density is not a cue: on real images it does not separate obstacles from what is
not one (docs/evaluation.md).
"""

from collections.abc import Mapping
from typing import Annotated

import msgspec

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.services.fusion.verifiers import appearance, create
from aeb_radar_camera.services.fusion.verifiers.base import (
    GateResult,
    Observation,
    ParamValue,
    Verifier,
    VerifierConfigError,
    parse_params,
)

APPEARANCE = ("hog_linear", "hog_people", "none")
SCORE = "cue_ratio_product"   # min(depth ratio, 1) x appearance ratio
# A ratio this large is "certainly passes"; it keeps scores finite for the tables.
_MAX_RATIO = 1000.0


class CombinedParams(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    tau: Annotated[float, msgspec.Meta(ge=0, le=100)] = 1.0
    appearance: str = "hog_linear"
    weights: str = ""           # hog_linear's weights file
    use_depth: bool = True
    depth_tau: Annotated[float, msgspec.Meta(gt=0, le=1)] = 0.15

    def __post_init__(self) -> None:
        if self.appearance not in APPEARANCE:
            raise ValueError(f"appearance must be one of {', '.join(APPEARANCE)}")
        if self.appearance == "none" and not self.use_depth:
            raise ValueError("no cue left: appearance 'none' and use_depth false")


def _ratio(score: float, threshold: float) -> float:
    if threshold <= 0:
        return _MAX_RATIO
    return min(max(score, 0.0) / threshold, _MAX_RATIO)


class Combined:
    """Depth and appearance (module docstring)."""

    name = "combined"
    needs_depth = False         # without depth, appearance alone decides (and says so)

    def __init__(self, p: CombinedParams) -> None:
        self.p = p
        self.uses_depth = p.use_depth   # fusion brings depth when the camera has it
        self.depth: Verifier | None = (create("depth", {"tau": p.depth_tau})
                                       if p.use_depth else None)
        self.look: Verifier | None = None
        self._look_tau = 0.0
        if p.appearance == "hog_linear":
            self.look = create("hog_linear", {"weights": p.weights})
            self._look_tau = float(self.look.params()["tau"])
        elif p.appearance == "hog_people":
            self.look = create("hog_people")
            assert isinstance(self.look, appearance.HogPeople)
            self._look_tau = appearance.sigmoid(self.look.p.tau)

    def params(self) -> dict[str, ParamValue]:
        out: dict[str, ParamValue] = dict(msgspec.structs.asdict(self.p))
        if self.look is not None:
            out["appearance_tau"] = self._look_tau
        return out

    def prepare(self, calibration: Calibration) -> None:
        """The cues' own preparation for a camera (the depth verifier's ray maps)."""
        for cue in (self.depth, self.look):
            prepare = getattr(cue, "prepare", None)
            if callable(prepare):
                prepare(calibration)

    def _look_ratio(self, obs: Observation) -> tuple[float, float]:
        assert self.look is not None
        result = self.look.verify(obs)
        score = result.score
        if self.p.appearance == "hog_people":
            score = appearance.sigmoid(score)
        return score, _ratio(score, self._look_tau)

    def verify(self, obs: Observation) -> GateResult:
        detail: dict[str, float] = {"decided_depth": 0.0, "decided_appearance": 0.0}
        have_depth = (self.depth is not None and obs.depth_m is not None
                      and obs.calibration is not None and obs.xy_m is not None)
        detail["depth_available"] = float(have_depth)
        ratios: dict[str, float] = {}
        if have_depth:
            assert self.depth is not None
            d = self.depth.verify(obs)
            detail["depth"] = d.score
            ratios["depth"] = detail["depth_ratio"] = _ratio(d.score, self.p.depth_tau)
        if have_depth and ratios["depth"] == 0.0:
            # Nothing stands at the range: the product is 0 whatever the appearance, so
            # appearance (the dearer cue) is not computed.
            detail["decided_depth"] = 1.0
            return GateResult(0.0, False, detail, SCORE)
        if self.look is not None:
            look, ratio = self._look_ratio(obs)
            detail["appearance"] = look
            ratios["appearance"] = detail["appearance_ratio"] = ratio
        if not ratios:
            # use_depth only, and this frame has no depth: nothing can confirm.
            return GateResult(0.0, False, detail, SCORE)
        cue = min(ratios, key=lambda k: ratios[k])
        detail[f"decided_{cue}"] = 1.0
        score = min(ratios.get("depth", 1.0), 1.0) * ratios.get("appearance", 1.0)
        if self.look is None:
            score = ratios["depth"]
        return GateResult(score, score >= self.p.tau, detail, SCORE)


def make(params: Mapping[str, ParamValue]) -> Verifier:
    p = parse_params(params, CombinedParams, "combined")
    try:
        return Combined(p)
    except VerifierConfigError as exc:
        raise VerifierConfigError(f"verifier 'combined': {exc}") from exc
