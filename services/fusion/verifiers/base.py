"""What every verifier shares: its input (`Observation`), its output (`GateResult`), the
`Verifier` protocol, parameter parsing and the configuration error.

Nothing here imports a verifier: the verifier modules import this one, and the name
table (`services.fusion.verifiers`) imports a verifier's module only when it is asked for.
"""

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Annotated, Protocol, TypeVar

import msgspec
import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.services.fusion.roi import Roi

ParamValue = float | int | str | bool
S = TypeVar("S", bound=msgspec.Struct)

Threshold = Annotated[float, msgspec.Meta(ge=0, le=2000)]
Fraction = Annotated[float, msgspec.Meta(ge=0, le=1)]


class VerifierConfigError(ValueError):
    """An unknown verifier name or an invalid parameter; the message names it."""


@dataclass(frozen=True, slots=True)
class Observation:
    """What the camera shows of one radar track: every verifier's input.

    `gray`: the frame, 2-D uint8 (common.imaging.decode_gray). `roi`: the padded box
    around the track's projected column, inside the frame and non-empty. `column`: the
    column's own box (z from 0 to the column height at the track), clipped to the frame.
    `range_m`: the track's radar range at the frame's time. `depth_m`: depth aligned to
    `gray` in metres (float32, 0 where there is no return), None when the camera has no
    depth. `calibration`: the calibration the column was projected with, and `xy_m` the
    track's (x, y) in its ground frame (the column's foot) at the frame's time; verifiers
    that place depth in 3-D need both (None when unknown)."""

    gray: np.ndarray
    roi: Roi
    column: Roi
    range_m: float
    depth_m: np.ndarray | None = None
    calibration: Calibration | None = None
    xy_m: tuple[float, float] | None = None


@dataclass(frozen=True, slots=True)
class GateResult:
    """`score` is what the verifier compares with its threshold, and `score_name` says
    what that number is ("edge_density", "depth_share", "probability", ...); `detail`
    says how it got there.

    `unverifiable`: the verifier found too little evidence either way (e.g. too few depth
    returns); unless the track's summed evidence confirms it, the camera cannot tell: the
    threat follows the kinematic rule's `cannot_tell_full_only` when set, else the
    decision's `unverifiable_policy`, as when no frame is usable. Only a verifier
    configured to say so sets it (`recall_first` with `missing = "unverifiable"`);
    `verified` is then False."""

    score: float
    verified: bool
    detail: dict[str, float] = field(default_factory=dict)
    score_name: str = "score"
    unverifiable: bool = False


class Verifier(Protocol):
    name: str
    # True: the verifier needs `Observation.depth_m`; without depth it cannot check.
    needs_depth: bool

    def params(self) -> dict[str, ParamValue]:
        """Every parameter, defaults included, as recorded with each decision."""
        ...

    def verify(self, obs: Observation) -> GateResult:
        """Check one track's observation."""
        ...


def wants_depth(v: Verifier) -> bool:
    """Whether fusion should bring this verifier the camera's depth: it needs depth, or it
    uses depth when a frame has some (`uses_depth = True`: the combined verifier, which
    falls back to appearance without it)."""
    return bool(v.needs_depth or getattr(v, "uses_depth", False))


def parse_params(params: Mapping[str, ParamValue], spec: type[S], name: str) -> S:
    """`params` (a mapping) validated into the verifier's parameter Struct `spec`; absent
    fields take their defaults. Raises VerifierConfigError naming the verifier and the
    field."""
    try:
        return msgspec.convert(dict(params), spec, strict=True)
    except msgspec.ValidationError as exc:
        raise VerifierConfigError(f"verifier {name!r}: invalid params: {exc}") from exc
