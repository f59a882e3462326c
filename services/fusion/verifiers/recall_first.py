"""The recall-first camera check (`recall_first`): a threat is vetoed only on positive
evidence that nothing stands at the radar's range.

For emergency braking a missed obstacle is a collision, and the camera check exists to
stop the radar's false targets (metal on the road, a sign overhead, a multipath ghost):
it may stop a brake only where the camera shows that nothing stands there. So the check
asks depth one question - does the column at the radar's range stand empty? - and
every other answer, "something is there" or "cannot tell", confirms the threat.

Depth (the column window of `depth.py`: the ROI's rows, the column box's columns widened
to `min_width_px` and to `lateral_m` either side of the radar's point at its range; a
band pixel is one whose ray at the track's distance r lies
`band_min_m` to `max_height_m` above the ground). Each band pixel with a return is
    at       its point lies at the range (r - tol <= d <= r + tol + extent_m) and above
             the floor: `min_obstacle_m` plus the height the road's depth error gives it
             (k_sigma x rms(r) x camera height / r; the road at the range is no obstacle)
    near     its point is nearer than r - tol, above the floor (something stands in
             front of the range)
    through  any other: the ray passed the range and met the road, the background or a
             surface farther away
with tol(r) = k_sigma x the D435's RMS depth error at r + margin_m (common/depth_error.py,
as `depth`). The band starts low (0.1 m) and `at` is counted as the surface it covers,
not as a share of the whole 0.3-2.2 m column, so a 0.4 m box, or the thin frame of a
bicycle, is seen where most of the column looks past it.

Per frame, in this order (`detail` says which with a 1: `depth_<...>`, `appearance_veto`):
    depth_sparse       less than `min_in_view` of the window about the radar's point
                       (`lateral_m` either side of it at its range) lies in the image
                       (`in_view`: the camera does not see where the radar does), or
                       fewer than `min_returns` band pixels with a return, or fewer
                       returns than `min_density` x the sensor's cover x the band
                       pixels an empty road would return from (`reach_px`: those
                       whose ray meets the ground within `return_range_m`; a ray above
                       the horizon, or one that meets the road beyond the depth's
                       range, returns nothing from an empty road). The sensor's cover
                       (`row_cover`) is the share of such pixels with a return across
                       the whole frame in the window's rows: depth cannot tell.
                       Relative to the sensor's own cover, so that a dense D435 column
                       that is mostly holes (a black, shiny or close obstacle it cannot
                       match) cannot tell, while a lidar's projected scan lines, 10-20 %
                       of the pixels everywhere, can; relative to the pixels that
                       could return, so that at 30-40 m, where most of the band looks
                       above the horizon or past the depth's range, an empty road that
                       returns from every pixel it can still tells.
    depth_confirms     at least `confirm_px` pixels at the range, covering at least
                       `confirm_area_m2` there (0.02 m2: a 14 cm square; a pixel spans
                       r / focal_px metres): a surface stands there, never vetoed,
                       whatever it looks like; where the at-pixels stand sideways is
                       reported with it (`extent`: `at_y_min_m` .. `at_y_max_m`, the
                       window's `window_y_min_m` .. `window_y_max_m` at the range, and
                       whether the window's columns beyond the at-pixels on either side
                       see through, `through_low_y` / `through_high_y`), for fusion to
                       take an object beside the path out of it
    depth_sees_through at least `through_share` of the returns see through: veto
    depth_ambiguous    neither
    depth_missing      the frame has no depth
Appearance (`weights`: a `hog_linear` file; none by default) is asked only where depth
neither confirms nor sees through, and vetoes only when it is confident: the classifier's
probability of an obstacle at most `appearance_veto_p`.

The score is the frame's log-likelihood ratio of "an obstacle stands there" (`llr`):
`confirm_llr` where depth confirms, `through_llr` (negative) where it sees through,
`appearance_llr` (negative) on a confident appearance veto, 0 where nothing is known;
verified iff llr >= 0. Fusion adds the frames' llr up per track (`[fusion.evidence]`), so
that one frame neither brakes nor vetoes. Missing evidence (sparse or missing depth, no
confident appearance) confirms the threat (`missing = "confirm"`) or, with `missing =
"unverifiable"` (deploy/fusion.toml), makes it unverifiable: fusion then takes the
track's evidence so far, and a track without a confirmation is one the camera cannot tell
yet - the kinematic rule's `cannot_tell_full_only` brakes for it from the full stage only
(else the decision's `unverifiable_policy` applies).

Where it stops: a structure that really stands at the range (a wall, a guard rail, a
pole) is confirmed - keeping those out of the brake is the corridor's job; a false target
with something standing behind it within `extent_m` is confirmed; without depth, and
without appearance weights, nothing is ever vetoed.
"""

import weakref
from collections.abc import Mapping
from typing import Annotated, Literal

import cv2
import msgspec
import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.depth_error import D435Noise
from aeb_radar_camera.services.fusion.evidence import (
    APPEARANCE_VETO,
    AT_Y_MAX,
    AT_Y_MIN,
    IN_VIEW,
    THROUGH_HIGH_Y,
    THROUGH_LOW_Y,
    WINDOW_Y_MAX,
    WINDOW_Y_MIN,
)
from aeb_radar_camera.services.fusion.verifiers.appearance import load_hog_linear
from aeb_radar_camera.services.fusion.verifiers.base import (
    GateResult,
    Observation,
    ParamValue,
    Verifier,
    VerifierConfigError,
    parse_params,
)
from aeb_radar_camera.services.fusion.verifiers.depth import (
    NO_RETURN_M,
    ColumnDepth,
    column_depth,
    ray_maps,
)

SCORE = "llr"
Metres = Annotated[float, msgspec.Meta(ge=0, le=100)]
Share = Annotated[float, msgspec.Meta(ge=0, le=1)]
Llr = Annotated[float, msgspec.Meta(ge=-20, le=20)]

# The per-frame outcomes, as gate_detail keys.
SPARSE, CONFIRMS, THROUGH, AMBIGUOUS, MISSING = (
    "depth_sparse", "depth_confirms", "depth_sees_through", "depth_ambiguous",
    "depth_missing")


class RecallFirstParams(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    band_min_m: Metres = 0.1
    max_height_m: Metres = 2.2
    min_obstacle_m: Metres = 0.12
    k_sigma: Annotated[float, msgspec.Meta(ge=0, le=10)] = 2.0
    margin_m: Metres = 0.3
    extent_m: Metres = 1.0
    focal_px: Annotated[float, msgspec.Meta(gt=0, le=10000)] = 449.0
    baseline_m: Annotated[float, msgspec.Meta(gt=0, le=1)] = 0.050
    subpixel: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.08
    min_width_px: Annotated[int, msgspec.Meta(ge=1, le=1000)] = 24
    # The window reaches this far either side of the radar's point at its range: a radar
    # reports an object's strongest reflection, which may be its edge (a cyclist ahead
    # is seen at the near edge of a 0.6 m body), so "nothing stands there" must hold
    # across the object's possible extent, not beside it.
    lateral_m: Metres = 0.5
    min_in_view: Share = 0.5
    min_returns: Annotated[int, msgspec.Meta(ge=1, le=100000)] = 12
    # Of the sensor's own cover in the window's rows (depth_sparse in the docstring).
    min_density: Share = 0.3
    # The farthest the depth returns: the wire's uint16 millimetres end at 65.5 m
    # (common/depth_image.py), whatever the sensor could do.
    return_range_m: Annotated[float, msgspec.Meta(gt=0, le=1000)] = 65.0
    confirm_px: Annotated[int, msgspec.Meta(ge=1, le=100000)] = 4
    confirm_area_m2: Annotated[float, msgspec.Meta(ge=0, le=10)] = 0.02
    through_share: Share = 0.9
    weights: str = ""               # hog_linear weights; empty: no appearance cue
    appearance_veto_p: Share = 0.02
    missing: Literal["confirm", "unverifiable"] = "confirm"
    confirm_llr: Llr = 1.5
    through_llr: Llr = -1.0
    appearance_llr: Llr = -0.5

    def __post_init__(self) -> None:
        if self.band_min_m >= self.max_height_m:
            raise ValueError("band_min_m must be below max_height_m")
        if self.confirm_llr <= 0 or self.through_llr >= 0 or self.appearance_llr >= 0:
            raise ValueError("confirm_llr must be positive, through_llr and "
                             "appearance_llr negative")


class RecallFirst:
    """The recall-first check (module docstring)."""

    name = "recall_first"
    needs_depth = False         # without depth it confirms (or says unverifiable)
    uses_depth = True
    gives_llr = True            # fusion sums it per track (and gathers it ahead of threats)

    def __init__(self, p: RecallFirstParams, look: Verifier | None) -> None:
        self.p = p
        self.look = look
        self.model = D435Noise(focal_px=p.focal_px, baseline_m=p.baseline_m,
                               subpixel=p.subpixel, hole_rate=0.0)
        # The pixels an empty road returns from (per calibration's ray slopes and the
        # camera's height: static), with their count per row, cumulated.
        self._reach: tuple[weakref.ref[np.ndarray], float, np.ndarray,
                           np.ndarray] | None = None
        # The last depth image's such pixels with a return per row, cumulated: every
        # track of a frame shares one image, so the frame is counted once, not once per
        # track.
        self._rows: tuple[weakref.ref[np.ndarray], np.ndarray, np.ndarray] | None = None

    def params(self) -> dict[str, ParamValue]:
        return msgspec.structs.asdict(self.p)

    def prepare(self, calibration: Calibration) -> None:
        """Compute the calibration's ray maps now rather than in the first verify()."""
        ray_maps(calibration)

    def tolerance_m(self, distance_m: float) -> float:
        return float(self.p.k_sigma * self.model.rms_m(distance_m) + self.p.margin_m)

    def row_cover(self, depth: np.ndarray, slope: np.ndarray, lowest: float, r0: int,
                  r1: int) -> float:
        """The share of the pixels of rows r0..r1 (the whole frame's width) an empty road
        would return from (their ray's `slope` at most `lowest`: it meets the ground within
        `return_range_m`) that have a return: the sensor's cover where it could see."""
        reach = self._reach
        if reach is None or reach[0]() is not slope or reach[1] != lowest:
            mask = slope <= lowest
            reach = (weakref.ref(slope), lowest, mask,
                     np.concatenate(([0], np.cumsum(np.count_nonzero(mask, axis=1)))))
            self._reach = reach
        rows = self._rows
        if rows is None or rows[0]() is not depth or rows[1] is not reach[2]:
            seen = np.count_nonzero(reach[2] & (depth > NO_RETURN_M), axis=1)
            rows = (weakref.ref(depth), reach[2], np.concatenate(([0], np.cumsum(seen))))
            self._rows = rows
        r0, r1 = max(r0, 0), min(r1, depth.shape[0])
        cum_reach = reach[3]
        if r1 <= r0 or cum_reach[r1] == cum_reach[r0]:
            return 0.0
        return float(rows[2][r1] - rows[2][r0]) / float(cum_reach[r1] - cum_reach[r0])

    def in_view_share(self, cal: Calibration, xy_m: tuple[float, float],
                      distance_m: float) -> float:
        """The share of the window about the radar's point `xy_m` (`lateral_m` either
        side at `distance_m`, at least `min_width_px`) within the image's columns."""
        p = self.p
        height = (p.band_min_m + p.max_height_m) / 2.0
        uv, in_front = cal.project(np.array([[xy_m[0], xy_m[1], height]]))
        if not in_front[0]:
            return 0.0
        u = float(uv[0, 0])
        half = max(p.min_width_px / 2.0,
                   p.lateral_m * float(cal.k[0, 0]) / max(distance_m, 0.1))
        seen = min(u + half, float(cal.width)) - max(u - half, 0.0)
        return min(max(seen / (2.0 * half), 0.0), 1.0)

    def _lowest_slope(self, camera_z_m: float) -> float:
        """The largest ray slope (rise / run) that still meets the ground within
        `return_range_m` of a camera `camera_z_m` above it: a pixel an empty road returns
        from has a ray at most this steep upwards."""
        return -camera_z_m / self.p.return_range_m

    def depth_evidence(self, obs: Observation) -> tuple[str, dict[str, float]]:
        """The depth outcome of one observation (one of the module's names) and its
        counts."""
        if obs.depth_m is None or obs.calibration is None or obs.xy_m is None:
            return MISSING, {}
        p = self.p
        col = column_depth(obs, p.min_width_px, p.band_min_m, p.max_height_m, p.lateral_m)
        r, cz = col.expected_m, col.camera_z_m
        tol = self.tolerance_m(r)
        n_band = cv2.countNonZero(col.band)
        n_ret = cv2.countNonZero(col.returns)
        # The road beyond the range, its depth short by the tolerance, rises to
        # tol x cz / r in the band's rays: "above the ground" is above that too.
        lift_tol = p.k_sigma * float(self.model.rms_m(r)) * max(cz, 0.0) / r
        detail_floor = p.min_obstacle_m + lift_tol
        above = cv2.inRange(col.lift, detail_floor - cz, np.inf)
        standing = cv2.bitwise_and(col.returns, above)
        at = cv2.bitwise_and(standing, cv2.inRange(
            col.dist, r - tol, r + tol + p.extent_m))
        near = cv2.bitwise_and(standing, cv2.inRange(col.dist, -np.inf, r - tol))
        n_at, n_near = cv2.countNonZero(at), cv2.countNonZero(near)
        n_through = n_ret - n_at - n_near
        detail = {"band_px": float(n_band), "returns": float(n_ret), "at_px": float(n_at),
                  "near_px": float(n_near), "through_px": float(n_through),
                  "expected_m": r, "tol_m": tol, "floor_m": detail_floor}
        detail[IN_VIEW] = in_view = self.in_view_share(obs.calibration, obs.xy_m, r)
        if in_view < p.min_in_view:
            return SPARSE, detail
        lowest = self._lowest_slope(col.camera_z_m)
        detail["row_cover"] = cover = self.row_cover(
            obs.depth_m, col.maps.slope, lowest, obs.roi.y,
            obs.roi.y + obs.roi.h)
        reach = cv2.bitwise_and(col.band, cv2.inRange(col.slope, -np.inf, lowest))
        detail["reach_px"] = n_reach = float(cv2.countNonZero(reach))
        if n_ret < p.min_returns or n_ret < p.min_density * cover * n_reach:
            return SPARSE, detail
        # The surface the pixels at the range cover there (a pixel spans r / f metres).
        detail["at_area_m2"] = area = n_at * (r / p.focal_px) ** 2
        if n_at >= p.confirm_px and area >= p.confirm_area_m2:
            detail.update(extent(col, at, cv2.bitwise_or(at, near), reach,
                                 p.min_density * cover))
            return CONFIRMS, detail
        if n_through >= p.through_share * n_ret:
            return THROUGH, detail
        return AMBIGUOUS, detail

    def verify(self, obs: Observation) -> GateResult:
        p = self.p
        outcome, detail = self.depth_evidence(obs)
        detail[outcome] = 1.0
        if outcome == CONFIRMS:
            llr = p.confirm_llr
        elif outcome == THROUGH:
            llr = p.through_llr
        else:
            llr = 0.0
            if self.look is not None:
                prob = self.look.verify(obs).score
                detail["appearance"] = prob
                if prob <= p.appearance_veto_p:
                    detail[APPEARANCE_VETO] = 1.0
                    llr = p.appearance_llr
        detail["llr"] = llr
        unverifiable = (p.missing == "unverifiable" and llr == 0.0
                        and outcome in (SPARSE, MISSING))
        return GateResult(llr, llr >= 0.0 and not unverifiable, detail, SCORE,
                          unverifiable=unverifiable)


def extent(col: ColumnDepth, at: np.ndarray, standing: np.ndarray, reach: np.ndarray,
           min_share: float) -> dict[str, float]:
    """Where the pixels `at` the range stand sideways (ground y, left positive: `at_y_min_m`,
    `at_y_max_m`), where the window lies at the range (`window_y_min_m`,
    `window_y_max_m`), and whether every column of the window beyond the at-pixels'
    columns on the low-y side (`through_low_y`) or the high-y side (`through_high_y`)
    sees through: 1 iff there is such a column and each has a return in at least
    `min_share` of its band pixels an empty road would return from (`reach`), at least
    one, and none `standing` (at or nearer than the range). Holes or too few returns
    cannot tell: 0."""
    ys = col.across()[at > 0]
    band = col.band > 0
    ray_across = col.ray_across()
    window = ray_across[band]
    cy = col.camera_y_m
    out = {AT_Y_MIN: float(ys.min()) + cy, AT_Y_MAX: float(ys.max()) + cy,
           WINDOW_Y_MIN: float(window.min()) + cy, WINDOW_Y_MAX: float(window.max()) + cy}
    n_band = np.count_nonzero(band, axis=0)
    n_reach = np.count_nonzero(reach, axis=0)
    n_ret = np.count_nonzero(col.returns, axis=0)
    clear = ((n_ret >= 1) & (n_ret >= min_share * n_reach)
             & (np.count_nonzero(standing, axis=0) == 0) & (n_band > 0))
    cols = np.flatnonzero(np.count_nonzero(at, axis=0))
    before, after = clear[:cols[0]], clear[cols[-1] + 1:]
    before_ok = float(before.size > 0 and bool(before.all()))
    after_ok = float(after.size > 0 and bool(after.all()))
    # The image's columns run right to left in the ground frame for a forward camera;
    # the ray maps say which way this window runs.
    rows = np.any(band, axis=1)
    line = ray_across[np.argmax(rows)] if rows.any() else ray_across[0]
    falling = bool(line[-1] < line[0])
    out[THROUGH_LOW_Y] = after_ok if falling else before_ok
    out[THROUGH_HIGH_Y] = before_ok if falling else after_ok
    return out


def make(params: Mapping[str, ParamValue]) -> Verifier:
    p = parse_params(params, RecallFirstParams, "recall_first")
    try:
        look = load_hog_linear({"weights": p.weights}) if p.weights else None
    except VerifierConfigError as exc:
        raise VerifierConfigError(f"verifier 'recall_first': {exc}") from exc
    return RecallFirst(p, look)
