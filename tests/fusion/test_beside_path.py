"""The camera's lateral extent: where depth confirms, the recall-first check says where the
pixels at the range stand sideways and whether the window's columns between them and the
path see through; fusion takes a track whose radar point lies in the path's margin out of
the path only on that evidence, and leaves a straddling object, a side-on car whose radar
point is at its outer end, and an object with holes beside it in the path."""

from typing import Any

import numpy as np
import pytest

from aeb_radar_camera.common.messages import Decision
from aeb_radar_camera.services.fusion.core import CycleResult
from aeb_radar_camera.services.fusion.evidence import (
    AT_Y_MAX,
    AT_Y_MIN,
    BESIDE_PATH,
    IN_VIEW,
    THROUGH_HIGH_Y,
    THROUGH_LOW_Y,
    WINDOW_Y_MAX,
    WINDOW_Y_MIN,
)
from aeb_radar_camera.services.fusion.frames import DecodedFrame
from aeb_radar_camera.services.fusion.verifiers import create
from tests.fusion.helpers import CAL, MS, T0, cycle, feed, make_core
from tests.fusion.test_decision_kinematic import KINEMATIC, Drive, ahead
from tests.fusion.test_depth_check import observe, render_depth

CHECK = create("recall_first")
X = 10.0
EDGE = 1.2                       # the radar point's distance from the path's centre


def beside(side: float) -> tuple[float, float, float, float, float, float]:
    """A 0.5 m wide object standing 0.3 m outside the ego's 1.8 m width on `side`."""
    lo, hi = sorted((side * EDGE, side * (EDGE + 0.5)))
    return (X, X + 0.6, lo, hi, 0.0, 1.7)


# Across the path's edge: its inner side 0.8 m from the centre, inside half_width_m.
STRADDLING = (X, X + 0.6, -1.5, -0.8, 0.0, 1.7)
# A car standing side-on across the lane, the radar's point at its outer (right) end.
SIDE_ON = (X, X + 1.8, -EDGE, -EDGE + 4.5, 0.0, 1.5)


def with_holes_beside(depth: np.ndarray) -> np.ndarray:
    """No return in the columns between the object beside on the right and the path."""
    obs = observe(depth, X, -EDGE)
    out = depth.copy()
    col = obs.column
    # The object's inner edge and the window's inner limit lie left of the column's
    # centre in the image (the ego's side): clear everything from there to the window's.
    mid = col.x + col.w // 2
    out[:, mid - 60:mid - 2] = 0.0
    return out


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_the_check_reports_an_object_beside_the_path_and_the_columns_between_seeing_through(
        side):
    got = CHECK.verify(observe(render_depth(CAL, boxes=(beside(side),)), X, side * EDGE))
    d = got.detail
    assert d["depth_confirms"] == 1.0 and got.verified
    inner, outer = (d[AT_Y_MIN], d[AT_Y_MAX])[::int(side)]
    assert abs(inner - side * EDGE) < 0.06 and abs(outer - side * (EDGE + 0.5)) < 0.06, d
    # The window reaches 0.5 m either side of the radar's point at its range.
    assert abs(d[WINDOW_Y_MIN] - (side * EDGE - 0.5)) < 0.06, d
    assert abs(d[WINDOW_Y_MAX] - (side * EDGE + 0.5)) < 0.06, d
    toward, away = (THROUGH_LOW_Y, THROUGH_HIGH_Y)[::int(side)]
    assert d[toward] == 1.0 and d[away] == 0.0, d


def test_a_straddling_object_is_measured_inside_the_path():
    d = CHECK.verify(observe(render_depth(CAL, boxes=(STRADDLING,)), X, -EDGE)).detail
    assert d["depth_confirms"] == 1.0
    assert abs(d[AT_Y_MAX] - -0.8) < 0.06, d


def test_a_side_on_car_fills_the_window_to_its_inner_edge():
    d = CHECK.verify(observe(render_depth(CAL, boxes=(SIDE_ON,)), X, -EDGE)).detail
    assert d["depth_confirms"] == 1.0
    assert d[AT_Y_MAX] >= d[WINDOW_Y_MAX] - 0.06 and d[THROUGH_HIGH_Y] == 0.0, d


def test_holes_between_the_object_and_the_path_cannot_tell():
    depth = with_holes_beside(render_depth(CAL, boxes=(beside(-1.0),)))
    d = CHECK.verify(observe(depth, X, -EDGE)).detail
    assert d["depth_confirms"] == 1.0 and d[AT_Y_MAX] < -EDGE + 0.06, d
    assert d[THROUGH_HIGH_Y] == 0.0, d


class DepthDrive(Drive):
    """Drive with the recall-first check, every radar cycle with a frame of `depth`."""

    def __init__(self, depth: np.ndarray | None, **decision: Any) -> None:
        super().__init__(make_core(decision={**KINEMATIC, **decision},
                                   verifier={"name": "recall_first"}))
        self.depth = depth

    def cycle(self, *tracks, dt_ms: int = 75) -> CycleResult:
        self.t += dt_ms * MS
        stamp = T0 + self.t
        f = DecodedFrame("front", self.seq, stamp, 0,
                         np.full((CAL.height, CAL.width), 100, np.uint8), self.depth)
        res = self.core.process(cycle(*tracks, seq=self.seq, stamp_ns=stamp), feed(f),
                                stamp + 5 * MS, self.t + 5 * MS)
        self.seq += 1
        return res


def decide(depth: np.ndarray | None, y: float = -EDGE + 0.05):
    """The first target of a cycle at 10 m/s towards a stationary track at (X, y): 1 s
    to go, a full brake when it is in the path."""
    drive = DepthDrive(depth)
    drive.step(10.0)
    return drive.step(10.0, ahead(X, 10.0, y=y)).targets.targets[0]


def test_a_track_in_the_margin_whose_object_stands_beside_the_path_is_not_braked_for():
    tgt = decide(render_depth(CAL, boxes=(beside(-1.0),)))
    assert tgt.decision is Decision.NONE and tgt.gate_detail[BESIDE_PATH] == 1.0, tgt
    head, _, rest = tgt.reason.partition("inner edge ")
    assert head == "beside the path by the camera: ", tgt.reason
    assert abs(float(rest.split()[0]) - -EDGE) < 0.06, tgt.reason
    assert rest.endswith("limit 0.9 + 0.2 m"), tgt.reason


@pytest.mark.parametrize("scene", ["straddling", "side_on", "holes", "no_depth"])
def test_without_evidence_that_the_path_is_clear_the_point_test_stands(scene):
    depth = {"straddling": render_depth(CAL, boxes=(STRADDLING,)),
             "side_on": render_depth(CAL, boxes=(SIDE_ON,)),
             "holes": with_holes_beside(render_depth(CAL, boxes=(beside(-1.0),))),
             "no_depth": None}[scene]
    tgt = decide(depth)
    assert tgt.decision is Decision.BRAKE and BESIDE_PATH not in tgt.gate_detail, tgt
    if depth is not None:
        # The camera measured the extent: the brake is its verdict, not its absence.
        assert AT_Y_MAX in tgt.gate_detail, tgt.gate_detail


def test_a_wider_camera_margin_keeps_the_object_in_the_path():
    drive = DepthDrive(render_depth(CAL, boxes=(beside(-1.0),)),
                       path={"camera_margin_m": 0.4})
    drive.step(10.0)
    tgt = drive.step(10.0, ahead(X, 10.0, y=-EDGE + 0.05)).targets.targets[0]
    assert tgt.decision is Decision.BRAKE and AT_Y_MAX in tgt.gate_detail, tgt


def test_every_threat_the_camera_takes_out_of_the_path_is_counted():
    beside_drive = DepthDrive(render_depth(CAL, boxes=(beside(-1.0),)))
    straddling_drive = DepthDrive(render_depth(CAL, boxes=(STRADDLING,)))
    for drive in (beside_drive, straddling_drive):
        drive.step(10.0)
        for _ in range(3):
            drive.step(10.0, ahead(X, 10.0, y=-EDGE + 0.05))
    assert beside_drive.core.beside_path_targets == 3
    assert straddling_drive.core.beside_path_targets == 0


class MovingDepthDrive(DepthDrive):
    """DepthDrive whose frame the test sets before each cycle."""

    def frame(self, depth: np.ndarray | None) -> None:
        self.depth = depth


def _passing(depth: np.ndarray, x: float, y: float = -EDGE + 0.03) -> Any:
    """The object beside the path seen whole 10 m ahead, then `x` ahead in `depth`: the
    target of that second cycle."""
    drive = MovingDepthDrive(render_depth(CAL, boxes=(beside(-1.0),)))
    drive.step(10.0)
    first = drive.step(10.0, ahead(X, 10.0, y=y)).targets.targets[0]
    assert first.gate_detail.get(BESIDE_PATH) == 1.0, first
    drive.frame(depth)
    return drive.step(10.0, ahead(x, 10.0, y=y)).targets.targets[0]


NEAR_X = 0.9      # the check's window half out of the image


def test_an_object_leaving_the_image_beside_the_ego_stays_beside_the_path():
    """Close beside the ego the check's window leaves the image and the columns between
    the object and the path return nothing (there the road lies below the image): no
    evidence either way, so the last verdict carries, as when no frame shows it. The
    same frame with the whole window in the image leaves the point test's brake."""
    near = (NEAR_X, NEAR_X + 0.6, -EDGE - 0.5, -EDGE, 0.0, 1.7)
    depth = render_depth(CAL, boxes=(near,))
    uv, _ = CAL.project(np.array([[NEAR_X, -EDGE, 0.8]]))    # the object's inner edge
    u = int(uv[0, 0])
    depth[:, u - 120:u - 2] = 0.0
    tgt = _passing(depth, NEAR_X)
    d = tgt.gate_detail
    assert d[IN_VIEW] < 1.0 and d.get(THROUGH_HIGH_Y, 0.0) == 0.0, d
    assert tgt.decision is Decision.NONE, tgt
    assert tgt.reason.endswith("(last seen 75 ms ago)"), tgt.reason
    # Not leaving the image: the holes are the frame's verdict, the point test brakes.
    far = with_holes_beside(render_depth(CAL, boxes=(beside(-1.0),)))
    tgt = _passing(far, X - 0.75)
    assert tgt.gate_detail[IN_VIEW] == 1.0, tgt.gate_detail
    assert tgt.decision is Decision.BRAKE and BESIDE_PATH not in tgt.gate_detail, tgt


def test_an_object_leaving_the_image_whose_pixels_reach_the_path_is_braked_for():
    near = (NEAR_X, NEAR_X + 0.6, -EDGE - 0.5, -0.7, 0.0, 1.7)
    tgt = _passing(render_depth(CAL, boxes=(near,)), NEAR_X)
    assert tgt.gate_detail[IN_VIEW] < 1.0, tgt.gate_detail
    assert AT_Y_MAX in tgt.gate_detail, tgt.gate_detail
    assert tgt.decision is Decision.BRAKE and BESIDE_PATH not in tgt.gate_detail, tgt
