"""The conversions shared by recordings and the live bridge, in-process: annotations on
the frame each ROI was checked in, colours by state, scaling, the plots' most severe
track, the health view, and bytes that decode with the schema they are written with."""

import json

import msgspec

from common.messages import Decision, Verification
from tests.foxglove.protobuf import decode
from tests.recording.publish import textured_jpeg
from tests.system.messages import brake_status, target, verified_targets
from tools.recording.foxglove_views import (
    Converter,
    encode_derived,
    frame_stamp_ns,
    state_colour,
    threat_plot,
)

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
    from common.messages import CompressedFrame
    from tests.system.messages import header

    frame = CompressedFrame(header=header(3, "camera/front", STAMP), camera="front", width=848,
                            height=480, jpeg=textured_jpeg())
    same = decoded(Converter("ego").image(frame))
    assert same.data == frame.jpeg and same.format == "jpeg"
    from common.imaging import decode_gray

    small = decoded(Converter("ego", scale=0.25).image(frame))
    assert decode_gray(small.data).shape == (120, 212)
    scene = decoded(Converter("ego").fusion_scene(targets()))
    ids = [e.id for e in scene.entities]
    assert ids == ["corridor", "track-7", "track-8", "track-9"]
    corridor = scene.entities[0]
    ys = sorted({round(p.y, 6) for line in corridor.lines[:4] for p in line.points})
    assert ys == [-1.2, -0.9, 0.9, 1.2]


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
