"""A frozen camera (the same picture with fresh timestamps) while the radar sees the scene
move is unavailable, "camera frozen", with a WARNING and a counter; a live camera, or a
still picture while nothing moves, is used as before."""

import logging

import numpy as np

from common.clock import wall_ns
from common.imaging import encode_jpeg, jpeg_crc32
from common.messages import CompressedFrame, Decision, Header, VerifierStatus, encode
from services.fusion.frames import FROZEN_REASON, FrameDecoder, same_picture
from services.fusion.shell import FusionShell
from tests.fusion.helpers import MS, T0, FixedVerifier, cycle, make_core, track
from tests.fusion.test_shell import FakeBus

W, H = 848, 480
FRAME_NS = 33 * MS


def picture(shift: int = 0, noise_seed: int | None = None) -> np.ndarray:
    """A road-like scene; `shift` moves it sideways, `noise_seed` adds sensor noise."""
    x = (np.arange(W) + shift) % W
    img = np.tile(((x * 7) % 256).astype(np.uint8)[None, :], (H, 1))
    img[300:, :] = 80
    if noise_seed is not None:
        noise = np.random.default_rng(noise_seed).integers(-3, 4, img.shape)
        img = np.clip(img.astype(np.int16) + noise, 0, 255).astype(np.uint8)
    return img


def payload(gray: np.ndarray, seq: int, stamp_ns: int) -> bytes:
    jpeg = encode_jpeg(gray, 80)
    return encode(CompressedFrame(header=Header(seq=seq, source="camera/front",
                                                stamp_ns=stamp_ns, pub_mono_ns=0),
                                  camera="front", width=W, height=H, jpeg=jpeg,
                                  crc32=jpeg_crc32(jpeg)))


def feed_frames(decoder: FrameDecoder, pictures: list[np.ndarray], t0: int = T0) -> int:
    """Frames 33 ms apart from `t0`, ending at the returned stamp."""
    stamp = t0
    for i, gray in enumerate(pictures):
        stamp = t0 + i * FRAME_NS
        decoder.decode_now(payload(gray, i, stamp), i)
    return stamp


CLOSING = track(x=10.0, vx=-8.3)      # a stationary car ahead at 30 km/h


def decide(decoder: FrameDecoder, core, stamp_ns: int, *tracks):
    return core.process(cycle(*tracks, stamp_ns=stamp_ns), decoder.snapshot(),
                        stamp_ns + 5 * MS, 1)


def test_a_repeated_picture_while_the_scene_moves_makes_the_camera_unavailable():
    decoder = FrameDecoder(W, H, logging.getLogger("test"))
    stamp = feed_frames(decoder, [picture()] * 30)         # one second of one picture
    result = decide(decoder, make_core(FixedVerifier()), stamp, CLOSING)
    assert result.targets.verifier_status is VerifierStatus.UNAVAILABLE
    assert result.targets.unavailable_reason == FROZEN_REASON
    assert result.targets.cameras_unavailable == {"front": FROZEN_REASON}
    # unverifiable_policy warn: no brake on a picture that proves nothing
    assert result.command.decision is Decision.WARNING


def test_a_picture_repeated_only_briefly_is_still_used():
    decoder = FrameDecoder(W, H, logging.getLogger("test"))
    stamp = feed_frames(decoder, [picture(s) for s in range(20)] + [picture(20)] * 5)
    result = decide(decoder, make_core(FixedVerifier()), stamp, CLOSING)
    assert result.targets.verifier_status is VerifierStatus.OK
    assert result.command.decision is Decision.BRAKE


def test_a_live_camera_is_used():
    decoder = FrameDecoder(W, H, logging.getLogger("test"))
    stamp = feed_frames(decoder, [picture(s * 3) for s in range(30)])
    result = decide(decoder, make_core(FixedVerifier()), stamp, CLOSING)
    assert result.targets.verifier_status is VerifierStatus.OK
    assert result.command.decision is Decision.BRAKE


def test_a_still_scene_seen_by_a_live_sensor_is_not_the_same_picture():
    assert same_picture(picture(), picture())
    assert not same_picture(picture(noise_seed=1), picture(noise_seed=2))
    assert not same_picture(picture(0), picture(1))


def test_a_still_picture_while_nothing_moves_is_not_frozen():
    decoder = FrameDecoder(W, H, logging.getLogger("test"))
    stamp = feed_frames(decoder, [picture()] * 30)
    parked = track(x=10.0, vx=0.0)                       # ego and car both standing
    result = decide(decoder, make_core(FixedVerifier()), stamp, parked)
    assert result.targets.verifier_status is VerifierStatus.OK


def test_the_check_can_be_turned_off():
    decoder = FrameDecoder(W, H, logging.getLogger("test"))
    stamp = feed_frames(decoder, [picture()] * 30)
    core = make_core(FixedVerifier(), frames={"frozen_after_s": 0.0})
    assert decide(decoder, core, stamp, CLOSING).targets.verifier_status is VerifierStatus.OK


def test_the_shell_warns_and_counts_a_frozen_camera(caplog):
    caplog.set_level(logging.WARNING, logger="test")
    # the shell judges the radar's age on the wall clock: room for encoding 30 frames
    core = make_core(FixedVerifier(), frames={"max_skew_s": 5.0},
                     decision={"radar_max_age_s": 5.0})
    decoder = FrameDecoder(W, H, logging.getLogger("test"))
    shell = FusionShell(FakeBus(), core.s, core, decoder,  # type: ignore[arg-type]
                        logging.getLogger("test"))
    stamp = feed_frames(decoder, [picture()] * 30, wall_ns() - 30 * FRAME_NS)
    for seq in range(3):
        shell.on_tracks_payload(encode(cycle(CLOSING, seq=seq, stamp_ns=stamp)), "k", 0)
    assert shell.stats()["camera_frozen"] == 3
    assert core.frozen_cycles == {"front": 3}
    frozen = [r for r in caplog.records if "camera_frozen" in r.getMessage()]
    assert len(frozen) == 1 and frozen[0].levelno == logging.WARNING
    assert "camera=front" in frozen[0].getMessage()
