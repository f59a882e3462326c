"""Several cameras in one radar cycle, and how their verdicts combine (pure).

Each camera has its own calibration (a ColumnProjector) and its own frames. Per cycle,
each camera picks its frame (frames.py), predicts every confirmed track to that frame's
capture time and projects it into its image. A track is then checked in the cameras that
see it, in configured order:

- **verified** if any camera verifies it; the first that does decides, and the cameras
  after it are not gated (their verdict could not change the outcome; they are reported
  `not_checked`);
- **rejected** if at least one camera with a usable frame sees it and every such camera
  rejects it; the deciding camera is the one with the highest density (the closest call);
- **not checked** when a camera with a usable frame sees it but the track is not gated
  (the gate scope, core.py);
- **unavailable** only if some camera would see it but none of those has a usable frame
  (for a verifier that needs depth, a frame is usable only with its depth);
- **not visible** only if no camera sees it (all project it behind themselves or outside
  their image).
"""

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.messages import RadarTrack, Verification
from aeb_radar_camera.common.messages.fusion import CameraCheck
from aeb_radar_camera.services.fusion.frames import (
    DecodedFrame,
    FrameFeed,
    select_frame,
    unavailable_reason,
)
from aeb_radar_camera.services.fusion.roi import ColumnProjector, Roi
from aeb_radar_camera.services.fusion.verifiers import GateResult, Observation

Gate = Callable[[Observation], GateResult]


@dataclass(frozen=True, slots=True)
class Camera:
    name: str
    projector: ColumnProjector


@dataclass(frozen=True, slots=True)
class CameraView:
    """One camera in one radar cycle: its frame (None: unavailable, `reason` says why),
    each track predicted to that frame's capture time (`xy`), and its ROI and column
    box (None: the camera does not see it)."""

    name: str
    frame: DecodedFrame | None
    reason: str
    xy: list[list[float]]
    rois: list[Roi | None]
    columns: list[Roi | None]
    calibration: Calibration | None = None


def _depth_reason(feed: FrameFeed, radar_stamp_ns: int, max_skew_ns: int) -> str:
    """Why no frame with depth could be used (the verifier needs depth)."""
    if not feed.frames:
        return unavailable_reason(feed, radar_stamp_ns, max_skew_ns)
    with_depth = tuple(f for f in feed.frames if f.depth_m is not None)
    if not with_depth:
        return ("no depth with the camera's frames (the verifier needs depth: "
                f"{feed.depth_received} depth images received, "
                f"{feed.depth_undecodable} unusable)")
    return "frames with depth: " + unavailable_reason(replace(feed, frames=with_depth),
                                                      radar_stamp_ns, max_skew_ns)


def camera_views(cameras: Sequence[Camera], feeds: Sequence[FrameFeed],
                 tracks: Sequence[RadarTrack], radar_stamp_ns: int, max_skew_ns: int,
                 align: bool, needs_depth: bool = False) -> list[CameraView]:
    """Every camera's frame and projections for one cycle. Tracks are predicted to the
    frame's time only with `align`; a camera without a usable frame projects them as
    they are (to tell "would see it" from "not visible"). `needs_depth`: only frames
    with their depth are usable."""
    pos = np.array([(t.x_m, t.y_m) for t in tracks], dtype=np.float64).reshape(-1, 2)
    vel = np.array([(t.vx_mps, t.vy_mps) for t in tracks], dtype=np.float64).reshape(-1, 2)
    views = []
    for cam, feed in zip(cameras, feeds, strict=True):
        frames = (tuple(f for f in feed.frames if f.depth_m is not None) if needs_depth
                  else feed.frames)
        frame = (None if feed.unusable_reason
                 else select_frame(frames, radar_stamp_ns, max_skew_ns, align))
        if frame is not None:
            reason = ""
        elif feed.unusable_reason:
            reason = feed.unusable_reason
        elif needs_depth:
            reason = _depth_reason(feed, radar_stamp_ns, max_skew_ns)
        else:
            reason = unavailable_reason(feed, radar_stamp_ns, max_skew_ns)
        dt_s = (frame.stamp_ns - radar_stamp_ns) / 1e9 if frame is not None and align else 0.0
        xy = pos + vel * dt_s
        boxes = cam.projector.boxes(xy) if len(xy) else []
        views.append(CameraView(cam.name, frame, reason, xy.tolist(),
                                [b[0] if b is not None else None for b in boxes],
                                [b[1] if b is not None else None for b in boxes],
                                cam.projector.cal))
    return views


@dataclass(frozen=True, slots=True)
class TrackCheck:
    """One track checked in every camera: the combined verification, the deciding
    camera's view (None when no camera sees it) and gate result, and each camera's own
    check (only when there are several cameras)."""

    verification: Verification
    view: CameraView | None
    roi: Roi | None
    result: GateResult | None
    per_camera: tuple[CameraCheck, ...] = ()


def check_track(i: int, views: Sequence[CameraView], gate: bool, verify: Gate) -> TrackCheck:
    """Track `i` in every camera, combined by the rule in the module docstring. `gate`:
    run the verifier (False: the gate scope does not gate this track)."""
    several = len(views) > 1
    verified: tuple[CameraView, Roi, GateResult] | None = None
    rejected: tuple[CameraView, Roi, GateResult] | None = None
    unchecked: tuple[CameraView, Roi] | None = None
    unavailable: CameraView | None = None
    per_camera: list[CameraCheck] = []
    for v in views:
        if verified is not None:
            # Its verdict could not change the outcome.
            if several:
                per_camera.append(CameraCheck(v.name, Verification.NOT_CHECKED))
            continue
        roi = v.rois[i]
        if roi is None:
            state, density = Verification.NOT_VISIBLE, None
        elif v.frame is None:
            state, density = Verification.UNAVAILABLE, None
            unavailable = unavailable or v
        elif not gate:
            state, density = Verification.NOT_CHECKED, None
            unchecked = unchecked or (v, roi)
        else:
            column = v.columns[i]
            assert column is not None           # a ROI always has its column
            x, y = v.xy[i]
            result = verify(Observation(v.frame.gray, roi, column, math.hypot(x, y),
                                        v.frame.depth_m, v.calibration, (x, y)))
            density = result.score
            if result.verified:
                state = Verification.VERIFIED
                verified = (v, roi, result)
            else:
                state = Verification.REJECTED
                if rejected is None or result.score > rejected[2].score:
                    rejected = (v, roi, result)
        if several:
            per_camera.append(CameraCheck(v.name, state, () if roi is None else tuple(roi),
                                          density))
    cams = tuple(per_camera)
    if verified is not None:
        return TrackCheck(Verification.VERIFIED, *verified, cams)
    if rejected is not None:
        return TrackCheck(Verification.REJECTED, *rejected, cams)
    if unchecked is not None:
        return TrackCheck(Verification.NOT_CHECKED, unchecked[0], unchecked[1], None, cams)
    if unavailable is not None:
        return TrackCheck(Verification.UNAVAILABLE, unavailable, None, None, cams)
    return TrackCheck(Verification.NOT_VISIBLE, None, None, None, cams)
