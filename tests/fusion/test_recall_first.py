"""The recall-first check: it vetoes only where depth sees through the column at the
radar's range; a small box, a surface at the range, sparse or missing depth and an
unknown appearance all confirm; appearance alone never vetoes what depth confirms."""

import subprocess
import sys

import numpy as np
import pytest

from aeb_radar_camera.common.depth_error import D435Noise
from aeb_radar_camera.common.depth_image import to_metres, to_units
from aeb_radar_camera.services.fusion.verifiers import (
    GateResult,
    Observation,
    VerifierConfigError,
    create,
)
from aeb_radar_camera.services.fusion.verifiers.base import ParamValue
from aeb_radar_camera.services.fusion.verifiers.recall_first import RecallFirst, RecallFirstParams
from aeb_radar_camera.tools.eval.depth import Box, box_scene_depth, car_box
from tests.fusion.helpers import CAL
from tests.fusion.test_depth_check import WIDE, observe, render_depth

CHECK = create("recall_first")


def box(x: float, edge: float = 0.4,
        y: float = 0.0) -> tuple[float, float, float, float, float, float]:
    """A cardboard box `edge` m a side standing on the road, its front at x."""
    return (x, x + edge, y - edge / 2, y + edge / 2, 0.0, edge)


def outcome(result: GateResult) -> str:
    (name,) = [k for k in result.detail if k.startswith("depth_")]
    return name


@pytest.mark.parametrize("x", [4.0, 8.0, 15.0, 25.0])
def test_a_0_4_m_box_at_the_range_is_confirmed(x):
    got = CHECK.verify(observe(render_depth(CAL, boxes=(box(x),)), x))
    assert got.verified and outcome(got) == "depth_confirms" and got.score > 0, got
    assert got.score_name == "llr"


@pytest.mark.parametrize("x", [4.0, 8.0, 15.0, 25.0])
def test_the_road_alone_is_seen_through_and_vetoed(x):
    got = CHECK.verify(observe(render_depth(CAL), x))
    assert not got.verified and outcome(got) == "depth_sees_through" and got.score < 0, got


def test_a_sign_overhead_or_a_plate_on_the_road_is_seen_through():
    sign = (12.0, 12.3, -2.0, 2.0, 4.5, 5.5)
    plate = (11.6, 12.4, -0.4, 0.4, 0.0, 0.02)
    for obstacle in (sign, plate):
        got = CHECK.verify(observe(render_depth(CAL, boxes=(obstacle,)), 12.0))
        assert not got.verified and outcome(got) == "depth_sees_through", got


def test_with_d435_noise_the_box_is_confirmed_and_the_road_still_vetoed():
    rng = np.random.default_rng(5)
    noise = D435Noise()
    for x in (6.0, 12.0, 20.0):
        with_box = noise.apply(render_depth(CAL, boxes=(box(x),)), rng)
        road = noise.apply(render_depth(CAL), rng)
        assert outcome(CHECK.verify(observe(with_box, x))) == "depth_confirms"
        assert outcome(CHECK.verify(observe(road, x))) == "depth_sees_through"


def test_something_nearer_than_the_range_is_never_vetoed():
    got = CHECK.verify(observe(render_depth(CAL, boxes=(box(6.0, 1.0),)), 12.0))
    assert got.verified and got.detail["near_px"] > 0, got


def test_sparse_or_missing_depth_confirms_or_follows_the_policy():
    depth = render_depth(CAL)
    sparse = np.zeros_like(depth)
    sparse[::16, ::16] = depth[::16, ::16]             # a few returns: cannot tell
    for d, name in ((sparse, "depth_sparse"), (None, "depth_missing")):
        got = CHECK.verify(observe(d, 12.0))
        assert got.verified and not got.unverifiable and outcome(got) == name, got
        strict = create("recall_first", {"missing": "unverifiable"}).verify(observe(d, 12.0))
        assert strict.unverifiable and not strict.verified, strict
    # No return at all in the band (a black, textureless column): sparse, not "empty".
    assert outcome(CHECK.verify(observe(render_depth(CAL, road=False), 12.0))) == \
        "depth_sparse"


def scan_lines(depth: np.ndarray, every: int = 7) -> np.ndarray:
    """Only every `every`-th row keeps its depth, as a lidar's scan lines projected into
    the image do (about 14 % of the pixels)."""
    out = np.zeros_like(depth)
    out[::every] = depth[::every]
    return out


@pytest.mark.parametrize("x", [6.0, 12.0, 20.0])
def test_sparse_scan_lines_everywhere_still_tell(x):
    """Density is judged against the sensor's own cover in those rows: a lidar's lines
    are few pixels but no holes, so the box is confirmed and the road seen through."""
    with_box = CHECK.verify(observe(scan_lines(render_depth(CAL, boxes=(box(x, 1.0),))), x,
                                    projector=WIDE))
    road = CHECK.verify(observe(scan_lines(render_depth(CAL)), x, projector=WIDE))
    assert outcome(with_box) == "depth_confirms", with_box
    assert outcome(road) == "depth_sees_through", road
    assert road.detail["row_cover"] < 0.2


def test_a_column_of_holes_in_a_dense_frame_cannot_tell():
    """The same share of returns as the scan lines, but only in the column while the
    rest of the frame is dense: the sensor failed there (a black or shiny obstacle it
    cannot match), and what it does see beyond must not veto."""
    x = 12.0
    obs = observe(render_depth(CAL), x, projector=WIDE)
    assert obs.depth_m is not None
    depth = obs.depth_m.copy()
    cols = slice(obs.column.x - 20, obs.column.x + obs.column.w + 20)
    window = depth[:, cols].copy()
    depth[:, cols] = 0.0
    depth[::7, cols] = window[::7]
    got = CHECK.verify(observe(depth, x, projector=WIDE))
    assert outcome(got) == "depth_sparse" and got.verified, got
    assert got.detail["row_cover"] > 0.4       # the sky above the horizon has no return


def test_where_the_camera_does_not_see_the_radars_point_it_cannot_tell():
    """A target at the image's edge: the window about the radar's point lies mostly
    outside the image, and what the part in view shows beyond it is not evidence that
    nothing stands at the point."""
    x = 5.0
    edge = [y for y in np.arange(-8.0, 0.0, 0.05)
            if WIDE.boxes(np.array([[x, y]]))[0] is not None]
    got = CHECK.verify(observe(render_depth(CAL), x, edge[0], projector=WIDE))
    assert outcome(got) == "depth_sparse" and got.verified, got
    assert got.detail["in_view"] < 0.5
    inside = CHECK.verify(observe(render_depth(CAL), x, edge[0] + 1.0, projector=WIDE))
    assert outcome(inside) == "depth_sees_through" and inside.detail["in_view"] > 0.99


def over_the_wire(depth: np.ndarray) -> np.ndarray:
    """Depth as a DepthFrame carries it: uint16 millimetres, no return beyond 65.5 m."""
    return to_metres(to_units(depth))


def far_scene(*boxes: Box) -> np.ndarray:
    return over_the_wire(box_scene_depth(CAL, boxes, max_range_m=1000.0))


@pytest.mark.parametrize("x", [32.0, 38.0])
def test_at_30_40_m_depth_still_tells_though_most_of_the_band_cannot_return(x):
    """At 30-40 m most of the band's rays look above the horizon or meet the road beyond
    the depth's range, so an empty road returns from under half of the band; judged
    against the pixels it could return from, the plate is seen through and a 1 m box is
    confirmed (a 0.4 m one is not told from the road there: the D435's depth error at
    30 m lifts the road as high)."""
    plate = (x - 0.4, x + 0.4, -0.4, 0.4, 0.0, 0.02)
    got = CHECK.verify(observe(far_scene(plate), x))
    assert outcome(got) == "depth_sees_through" and not got.verified, got
    d = got.detail
    assert d["returns"] < 0.5 * d["band_px"] and d["returns"] >= 0.9 * d["reach_px"], d
    with_box = CHECK.verify(observe(far_scene(box(x, 1.0)), x))
    assert outcome(with_box) == "depth_confirms" and with_box.verified, with_box


def test_at_35_m_a_car_the_sensor_cannot_match_cannot_tell():
    """Every pixel of the car a hole (black paint, no texture): what the window sees
    beside and below it is too little of what an empty road returns to veto."""
    x = 35.0
    road, with_car = far_scene(), far_scene(car_box(x))
    holes = np.where(with_car != road, 0.0, with_car).astype(np.float32)
    got = CHECK.verify(observe(holes, x))
    assert outcome(got) == "depth_sparse" and got.verified, got


class Look:
    """An appearance cue that answers a fixed probability."""

    name = "look"
    needs_depth = False

    def __init__(self, prob: float) -> None:
        self.prob = prob

    def params(self) -> dict[str, ParamValue]:
        return {}

    def verify(self, obs: Observation) -> GateResult:
        return GateResult(self.prob, self.prob >= 0.5, score_name="probability")


def test_appearance_never_vetoes_what_depth_confirms():
    sure_not = RecallFirst(RecallFirstParams(), Look(0.0))
    x = 10.0
    got = sure_not.verify(observe(render_depth(CAL, boxes=(box(x),)), x, projector=WIDE))
    assert got.verified and outcome(got) == "depth_confirms", got
    assert "appearance" not in got.detail      # not even asked


def test_appearance_vetoes_only_when_confident_and_depth_cannot_tell():
    obs = observe(None, 10.0)
    assert not RecallFirst(RecallFirstParams(), Look(0.01)).verify(obs).verified
    unsure = RecallFirst(RecallFirstParams(), Look(0.3)).verify(obs)
    assert unsure.verified and unsure.score == 0.0, unsure
    vetoed = RecallFirst(RecallFirstParams(), Look(0.01)).verify(obs)
    assert vetoed.detail["appearance_veto"] == 1.0 and vetoed.score < 0


def test_bad_params_are_refused():
    with pytest.raises(VerifierConfigError, match="recall_first"):
        create("recall_first", {"through_llr": 1.0})
    with pytest.raises(VerifierConfigError, match="recall_first"):
        create("recall_first", {"missing": "maybe"})
    with pytest.raises(VerifierConfigError, match="recall_first"):
        create("recall_first", {"weights": "/nonexistent/w.json"})


def test_the_name_table_imports_a_verifier_only_when_it_is_asked_for():
    code = ("import sys; import aeb_radar_camera.services.fusion.verifiers as v; "
            "before = sorted(m for m in sys.modules if m.startswith(v.__name__ + '.')); "
            "v.create('edge_density'); "
            "after = sorted(m for m in sys.modules if m.startswith(v.__name__ + '.')); "
            "print(before, after)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == ("['aeb_radar_camera.services.fusion.verifiers.base'] "
                           "['aeb_radar_camera.services.fusion.verifiers.base', "
                           "'aeb_radar_camera.services.fusion.verifiers.edge']"), out


@pytest.mark.parametrize("x", [3.5, 4.0])
def test_an_object_beside_the_radars_point_is_not_seen_through(x):
    # The radar reports a cyclist ahead near the edge of its 0.6 m body (0.15 m off
    # it, within its lateral error): the window must reach across the body's possible
    # extent, or it looks past it at the road and vetoes.
    body = (x, x + 1.75, -0.75, -0.15, 0.0, 1.75)
    obs = observe(render_depth(CAL, boxes=(body,)), x, y=0.0)
    narrow = RecallFirst(RecallFirstParams(lateral_m=0.0), None).verify(obs)
    assert outcome(narrow) == "depth_sees_through" and not narrow.verified, narrow
    got = CHECK.verify(obs)
    assert got.verified and outcome(got) == "depth_confirms", got


def test_the_road_beside_a_false_target_still_sees_through():
    obs = observe(render_depth(CAL), 4.0, y=-0.1)
    got = CHECK.verify(obs)
    assert not got.verified and outcome(got) == "depth_sees_through", got
