"""The conversions shared by recordings and the live bridge, in-process: annotations on
the frame each ROI was checked in, colours by state, scaling, the plots' most severe
track, the health view, and bytes that decode with the schema they are written with."""

import json

import msgspec
import numpy as np
import pytest

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.messages import Decision, Verification
from aeb_radar_camera.common.resources import EXAMPLE_CALIBRATION
from aeb_radar_camera.tools.recording.foxglove_views import (
    Converter,
    encode_derived,
    frame_stamp_ns,
    state_colour,
    threat_plot,
)
from tests.eval.fixtures import camera_info
from tests.foxglove.protobuf import decode
from tests.recording.publish import textured_jpeg
from tests.system.messages import brake_status, target, verified_targets

STAMP = 1_800_000_000_000_000_000


def decoded(view):
    """A Foxglove message as it is written, read back with its own schema."""
    kind, data = encode_derived(view)
    return decode(kind.schema_name, kind.schema_data, data)


def targets():
    brake = msgspec.structs.replace(target(7, 10.0, Decision.BRAKE, Verification.VERIFIED),
                                    camera="front", frame_age_ms=12.5)
    other = msgspec.structs.replace(target(8, 20.0, Decision.NONE, Verification.REJECTED,
                                           0.01), camera="side", frame_seq=5,
                                    frame_age_ms=-3.0, roi_xywh=(10, 20, 30, 40))
    unseen = msgspec.structs.replace(target(9, 24.0, Decision.NONE, Verification.NOT_VISIBLE,
                                            None), roi_xywh=(), frame_seq=None,
                                     frame_age_ms=None)
    return verified_targets("primary", 4, (brake, other, unseen), stamp_ns=STAMP)


def test_annotations_go_to_each_camera_stamped_with_the_frame_checked():
    msg = targets()
    anns = Converter("ego").annotations(msg)
    assert set(anns) == {"front", "side"}
    kind, _ = encode_derived(anns["front"])
    assert kind.schema_name == "foxglove.ImageAnnotations" and kind.message_encoding == \
        "protobuf"
    back = decoded(anns["front"])
    (box,) = back.points
    assert frame_stamp_ns(msg, msg.targets[0]) == STAMP - 12_500_000
    assert box.timestamp.seconds * 10**9 + box.timestamp.nanos == STAMP - 12_500_000
    assert [(p.x, p.y) for p in back.points[0].points] == [(100, 100), (150, 100),
                                                           (150, 180), (100, 180)]
    assert back.texts[0].text == "#7 10.0 m TTC 2.0 s edge_density 0.08 verified BRAKE"
    assert state_colour(msg.targets[0]) == (0.95, 0.1, 0.1, 1.0)      # BRAKE: red
    assert state_colour(msg.targets[1])[2] == 1.0                      # rejected: blue
    half = decoded(Converter("ego", scale=0.5).annotations(msg)["side"])
    assert (half.points[0].points[0].x, half.points[0].points[0].y) == (5, 10)


def test_images_scale_and_scenes_draw_the_corridor():
    from aeb_radar_camera.common.messages import CompressedFrame
    from tests.system.messages import header

    frame = CompressedFrame(header=header(3, "camera/front", STAMP), camera="front", width=848,
                            height=480, jpeg=textured_jpeg())
    same = decoded(Converter("ego").image(frame))
    assert same.data == frame.jpeg and same.format == "jpeg"
    from aeb_radar_camera.common.imaging import decode_gray

    small = decoded(Converter("ego", scale=0.25).image(frame))
    assert decode_gray(small.data).shape == (120, 212)
    scene = decoded(Converter("ego").fusion_scene(targets()))
    ids = [e.id for e in scene.entities]
    assert ids == ["corridor", "track-7", "track-8", "track-9"]
    corridor = scene.entities[0]
    ys = sorted({round(p.y, 6) for line in corridor.lines[:4] for p in line.points})
    assert ys == [-1.2, -0.9, 0.9, 1.2]


def test_the_scene_draws_the_kinematic_rules_arc_to_its_range_gate():
    from aeb_radar_camera.services.fusion.path import PredictedPath

    bend = msgspec.structs.replace(targets(), path="path R 50 m left (yaw rate)",
                                   path_curvature_per_m=0.02, range_gate_m=40.0)
    corridor = decoded(Converter("ego").fusion_scene(bend)).entities[0]
    assert corridor.id == "corridor" and corridor.metadata[0].value == bend.path
    outer_left = corridor.lines[3]          # half-width + margin, left
    end = outer_left.points[-1]
    arc = PredictedPath(0.02, 1.2, 80.0)
    assert (end.x, end.y) == pytest.approx(arc.at(40.0, 1.2), abs=1e-6)
    assert end.y > 10.0                     # bent left, not straight ahead at y = 1.2
    near = corridor.lines[4].points         # the near bound across the path
    assert [c for q in near for c in (q.x, q.y)] == pytest.approx(
        [*arc.at(0.5, -1.2), *arc.at(0.5, 1.2)], abs=1e-6)


def test_the_plots_and_the_health_view():
    plot = threat_plot(targets())
    assert (plot.track_id, plot.decision_level, plot.threshold) == (7, 2, 0.025)
    empty = threat_plot(verified_targets("primary", 1, ()))
    assert empty.track_id == -1 and empty.confirmed == 0
    conv = Converter("ego")
    topic, _ = conv.health("fusion", "primary", True)
    assert topic == "/foxglove/ego/health"
    derived = conv.convert("brake_status", brake_status(1))
    topics = [t for t, _ in derived]
    assert topics == ["/foxglove/ego/brake/plot", "/foxglove/ego/health"]
    health = json.loads(encode_derived(derived[1][1])[1])
    assert {(s["service"], s["alive"], s["status"]) for s in health["services"]} == {
        ("fusion", True, "unknown"), ("brake", False, "ok")}
    assert conv.convert("brake_status", brake_status(2))[1:] == []   # unchanged: no repeat


def _rotate(q, v):
    """A vector rotated by a unit quaternion (x, y, z, w)."""
    x, y, z, w = q
    u = np.array([x, y, z])
    v = np.asarray(v, float)
    return v + 2 * np.cross(u, np.cross(u, v) + w * v)


def test_camera_info_gives_the_calibration_and_the_cameras_place_in_the_radar_frame():
    # the shipped calibration (a camera above and behind the radar, pitched): the 3D
    # panel must put the image where fusion projects the tracks
    cal = Calibration.load(EXAMPLE_CALIBRATION)
    info = camera_info(cal, STAMP)
    views = dict(Converter("ego").convert("camera_info", info))
    calib = decoded(views["/foxglove/ego/camera/front/calibration"])
    assert calib.frame_id == "front" and (calib.width, calib.height) == (cal.width,
                                                                       cal.height)
    assert list(calib.K) == pytest.approx(cal.k.ravel().tolist())
    assert calib.distortion_model == "plumb_bob"
    (tf,) = decoded(views["/foxglove/ego/tf"]).transforms
    assert (tf.parent_frame_id, tf.child_frame_id) == ("radar", "front")
    q = (tf.rotation.x, tf.rotation.y, tf.rotation.z, tf.rotation.w)
    centre = np.array([tf.translation.x, tf.translation.y, tf.translation.z])
    assert centre == pytest.approx(cal.camera_position_m)
    # a point in front of the radar: through the camera frame and back by the transform
    ground = np.array([[12.0, -1.5, 0.8]])
    in_camera = cal.to_camera(ground)[0]
    assert centre + _rotate(q, in_camera) == pytest.approx(ground[0])
    # ... and the calibration's K puts it on the pixel fusion projects it to
    k = np.array(calib.K).reshape(3, 3)
    u, v, s = k @ in_camera
    uv, _ = cal.project(ground)
    if not np.any(cal.dist):
        assert (u / s, v / s) == pytest.approx(tuple(uv[0]), abs=1e-6)
    # scaled images (the bridge's --scale) have their intrinsics scaled with them
    half = decoded(dict(Converter("ego", scale=0.5).convert("camera_info", info))[
        "/foxglove/ego/camera/front/calibration"])
    assert half.width == round(cal.width / 2) and half.K[0] == pytest.approx(cal.k[0, 0] / 2)
