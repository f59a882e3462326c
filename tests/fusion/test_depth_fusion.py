"""Fusion with depth: DepthFrames decoded and paired with their colour frame by capture
stamp, and a depth verifier that only uses frames with depth (else the camera is
unavailable, saying why) while other verifiers ignore depth."""

import logging

import numpy as np
import pytest

from aeb_radar_camera.common.depth_image import encode_depth, to_metres, to_units
from aeb_radar_camera.common.messages import (
    DepthFrame,
    Header,
    Verification,
    VerifierStatus,
    encode,
)
from aeb_radar_camera.services.fusion.frames import FrameDecoder, FrameError, decode_depth_frame
from tests.fusion.helpers import CAL, T0, feed, frame, make_core, run, track
from tests.fusion.test_depth_check import car, render_depth
from tests.fusion.test_frames import compressed

W, H = CAL.width, CAL.height


def depth_payload(depth_m: np.ndarray, stamp_ns: int = T0, decimation: int = 2,
                  codec: str = "zstd") -> bytes:
    units = to_units(depth_m)[::decimation, ::decimation]
    return encode(DepthFrame(header=Header(0, "camera/front", stamp_ns, 0), camera="front",
                             width=units.shape[1], height=units.shape[0], codec=codec,
                             data=encode_depth(units, codec)))


def test_a_decimated_depth_frame_comes_back_in_metres_at_the_frame_size():
    depth = render_depth(CAL, boxes=(car(10.0),))
    stamp, got = decode_depth_frame(depth_payload(depth, decimation=2), W, H)
    assert stamp == T0 and got.shape == (H, W) and got.dtype == np.float32
    # Each depth pixel covers its 2x2 block of colour pixels.
    assert np.array_equal(got[0::2, 0::2], to_metres(to_units(depth))[0::2, 0::2])
    assert np.array_equal(got[1::2, 1::2], got[0::2, 0::2])
    _, full = decode_depth_frame(depth_payload(depth, decimation=1, codec="png"), W, H)
    assert np.allclose(full[depth < 65], depth[depth < 65], atol=6e-4)


@pytest.mark.parametrize(("payload", "reason"), [
    (b"\x93garbage", "depth_message"),
    (depth_payload(np.ones((480, 640), np.float32), decimation=1), "depth_size"),
    (depth_payload(np.ones((480, 848), np.float32), decimation=3), "depth_size"),
])
def test_unusable_depth_raises_with_a_reason(payload, reason):
    with pytest.raises(FrameError) as err:
        decode_depth_frame(payload, W, H)
    assert err.value.reason == reason


def test_a_corrupt_depth_payload_is_a_codec_error():
    msg = DepthFrame(header=Header(0, "camera/front", T0, 0), camera="front", width=424,
                     height=240, codec="zstd", data=b"\x28junk")
    with pytest.raises(FrameError) as err:
        decode_depth_frame(encode(msg), W, H)
    assert err.value.reason == "depth_codec"


def test_depth_pairs_with_its_frame_whichever_arrives_first():
    dec = FrameDecoder(W, H, logging.getLogger("test"))
    depth = render_depth(CAL, boxes=(car(10.0),))
    dec.decode_depth_now(depth_payload(depth, T0))          # before its frame
    dec.decode_now(compressed(T0, seq=1), 5)
    dec.decode_now(compressed(T0 + 33_000_000, seq=2), 6)
    dec.decode_depth_now(depth_payload(depth, T0 + 33_000_000))   # after its frame
    dec.decode_now(compressed(T0 + 66_000_000, seq=3), 7)       # never gets depth
    dec.decode_depth_now(depth_payload(depth, T0 + 99_000_000))   # no frame (yet)
    dec.decode_depth_now(b"\x93garbage")
    snap = dec.snapshot()
    assert [f.seq for f in snap.frames] == [1, 2, 3]
    assert [f.depth_m is not None for f in snap.frames] == [True, True, False]
    assert snap.depth_undecodable == 1 and dec.errors_by_reason == {"depth_message": 1}
    dec.decode_now(compressed(T0 + 99_000_000, seq=4), 8)
    assert dec.snapshot().frames[-1].depth_m is not None


def test_the_worker_decodes_submitted_depth():
    from tests.support import wait_for

    dec = FrameDecoder(W, H, logging.getLogger("test"))
    dec.start()
    try:
        dec.submit(compressed(T0, seq=1), "k", 1)
        dec.submit_depth(depth_payload(render_depth(CAL), T0), "k", 2)
        wait_for(lambda: any(f.depth_m is not None for f in dec.snapshot().frames), 30,
                 what="frame with depth")
        assert dec.snapshot().depth_received == 1
    finally:
        dec.stop()


def with_depth(depth_m: np.ndarray | None, stamp_ns: int = T0):
    f = frame(stamp_ns)
    return f if depth_m is None else type(f)(f.camera, f.seq, f.stamp_ns, f.rx_mono_ns,
                                             f.gray, depth_m)


def test_the_depth_verifier_in_fusion_verifies_an_obstacle_and_rejects_the_road():
    core = make_core(verifier={"name": "depth"})
    t = track(x=10.0, vx=-8.0)
    got = run(core, t, frames=feed(with_depth(render_depth(CAL, boxes=(car(10.0),)))))
    tgt = got.targets.targets[0]
    assert tgt.verification is Verification.VERIFIED and tgt.density > 0.8
    assert got.targets.verifier == "depth" and "tol_m" in tgt.gate_detail
    core = make_core(verifier={"name": "depth"})
    got = run(core, t, frames=feed(with_depth(render_depth(CAL))))
    assert got.targets.targets[0].verification is Verification.REJECTED


def test_without_depth_a_depth_verifier_finds_the_camera_unavailable_and_says_why():
    core = make_core(verifier={"name": "depth"})
    got = run(core, track(x=10.0, vx=-8.0), frames=feed(with_depth(None), depth_received=0))
    assert got.targets.verifier_status is VerifierStatus.UNAVAILABLE
    assert got.targets.targets[0].verification is Verification.UNAVAILABLE
    assert "no depth with the camera's frames" in got.targets.unavailable_reason
    # A frame with depth is preferred to a nearer one without.
    frames = feed(with_depth(render_depth(CAL, boxes=(car(10.0),)), T0 - 30_000_000),
                  with_depth(None, T0))
    got = run(make_core(verifier={"name": "depth"}), track(x=10.0, vx=-8.0), frames=frames,
              stamp_ns=T0)
    assert got.targets.targets[0].verification is Verification.VERIFIED
    # Other verifiers do not need depth: the same frame without depth is used.
    got = run(make_core(verifier={"name": "edge_density"}), track(x=10.0, vx=-8.0),
              frames=feed(with_depth(None)))
    assert got.targets.verifier_status is VerifierStatus.OK


class SubscribingBus:
    """What FusionShell.start needs: records each raw subscription's key and callback."""

    def __init__(self) -> None:
        self.subs: dict[str, object] = {}

    def publisher(self, spec, **params):
        return None

    def subscribe_raw(self, spec, callback, **params):
        self.subs[spec.name] = callback
        return type("Sub", (), {"undeclare": lambda self: None})()

    subscribe = subscribe_raw


@pytest.mark.parametrize(("verifier", "subscribed"), [("depth", True),
                                                      ("edge_density", False)])
def test_the_shell_subscribes_to_depth_only_for_a_verifier_that_needs_it(verifier, subscribed):
    from aeb_radar_camera.services.fusion.shell import FusionShell

    bus = SubscribingBus()
    core = make_core(verifier={"name": verifier})
    dec = FrameDecoder(W, H, logging.getLogger("test"))
    shell = FusionShell(bus, core.s, core, dec, logging.getLogger("test"))  # type: ignore[arg-type]
    shell.start()
    try:
        assert ("camera_depth" in bus.subs) is subscribed
        if subscribed:
            assert bus.subs["camera_depth"] == dec.submit_depth
    finally:
        shell.stop()
