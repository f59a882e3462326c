"""The camera's lateral extent the other way (`[fusion.decision.path] camera_into_m`): a
track whose radar point lies beyond the path's edge is in the path when depth shows its
object's surface at the range running on, window by window, into the path - a car
standing side-on across the lane whose radar point is its far corner - and stays out of it
where the surface stops short of the path or the columns between see through."""

from typing import Any

from aeb_radar_camera.common.messages import Decision
from aeb_radar_camera.services.fusion.core import CycleResult
from aeb_radar_camera.services.fusion.evidence import INTO_PATH
from aeb_radar_camera.tools.eval.depth import Box
from tests.fusion.helpers import CAL
from tests.fusion.test_beside_path import DepthDrive, X
from tests.fusion.test_decision_kinematic import ahead
from tests.fusion.test_depth_check import render_depth

FAR_CORNER = -2.4                # the radar's point: 2.4 m right of the path's centre
# A car standing side-on across the lane, its right end at the radar's point.
SIDE_ON: Box = (X, X + 1.8, FAR_CORNER, FAR_CORNER + 4.5, 0.0, 1.5)
# A car parked along the road, its inner side 2.4 m from the centre, the radar's point at
# its outer side.
PARKED: Box = (X, X + 4.5, FAR_CORNER - 1.8, FAR_CORNER, 0.0, 1.5)
PARKED_POINT = FAR_CORNER - 1.8
# A car ahead in the lane at the same range.
LEAD: Box = (X, X + 4.5, -0.9, 0.9, 0.0, 1.5)
INTO: dict[str, Any] = {"path": {"camera_into_m": 3.0}}


def cycles(*boxes: Box, y: float = FAR_CORNER,
           **decision: Any) -> tuple[CycleResult, CycleResult]:
    """The targets of two cycles at 10 m/s towards a stationary track at (X, y): 1 s to
    go, a full brake once it is in the path."""
    drive = DepthDrive(render_depth(CAL, boxes=boxes), **decision)
    drive.step(10.0)
    first = drive.step(10.0, ahead(X, 10.0, y=y))
    second = drive.step(10.0, ahead(X - 0.75, 10.0, y=y))
    return first, second


def test_a_side_on_car_whose_radar_point_is_its_far_corner_is_in_the_path():
    first, second = cycles(SIDE_ON, **INTO)
    # The first cycle the camera looks beside the radar's point; from the next the track
    # is in the path, and braked for.
    assert first.command.decision is Decision.NONE
    tgt = second.targets.targets[0]
    assert second.command.decision is Decision.BRAKE, tgt.reason
    assert "in path by the camera (its surface at the range reaches" in tgt.reason
    assert tgt.in_path and tgt.gate_detail[INTO_PATH] == 1.0


def test_without_the_setting_the_point_test_stands():
    _, second = cycles(SIDE_ON)
    tgt = second.targets.targets[0]
    assert second.command.decision is Decision.NONE and not tgt.in_path, tgt.reason
    assert INTO_PATH not in tgt.gate_detail


def test_a_car_beside_the_path_stays_beside_it():
    # Its surface runs from the radar's point toward the path and stops 2.4 m from the
    # centre; a car ahead in the lane at the same range does not join it.
    for boxes in ((PARKED,), (PARKED, LEAD)):
        _, second = cycles(*boxes, y=PARKED_POINT, **INTO)
        parked = next(t for t in second.targets.targets if t.y_m < -2.0)
        assert not parked.in_path and INTO_PATH not in parked.gate_detail, parked.reason
        assert second.command.decision is Decision.NONE


def test_a_radar_point_farther_beyond_the_path_than_the_setting_is_not_followed():
    _, second = cycles(SIDE_ON, path={"camera_into_m": 1.0})
    assert not second.targets.targets[0].in_path
