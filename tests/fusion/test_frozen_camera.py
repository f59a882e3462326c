"""A frozen camera (the same picture with fresh timestamps, with or without fresh sensor
noise) while the tracks say its picture must change is unavailable, "camera frozen", with
a WARNING and a counter; a live camera, or a still picture while nothing moves, is used
as before."""

import logging

import numpy as np
import pytest

from aeb_radar_camera.common.clock import wall_ns
from aeb_radar_camera.common.imaging import encode_jpeg, jpeg_crc32
from aeb_radar_camera.common.messages import (
    CompressedFrame,
    Decision,
    Header,
    VerifierStatus,
    encode,
)
from aeb_radar_camera.services.fusion.frames import (
    EXPECTED_CHANGE_MIN_PX,
    FROZEN_REASON,
    FrameDecoder,
    coarse,
    expected_change_px,
    same_picture,
)
from aeb_radar_camera.services.fusion.roi import ColumnProjector
from aeb_radar_camera.services.fusion.shell import FusionShell
from aeb_radar_camera.tools.sim.scenes import Obstacle, Scene, render
from tests.fusion.helpers import CAL, MS, T0, FixedVerifier, cycle, make_core, track
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


def projector() -> ColumnProjector:
    return make_core(FixedVerifier()).projector


def gaussian(img: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    noise = np.random.default_rng(seed).normal(0.0, sigma, img.shape)
    return np.clip(img + noise, 0, 255).astype(np.uint8)


def test_sensor_noise_is_the_same_picture_and_motion_is_not():
    assert same_picture(coarse(picture()), coarse(picture()))
    assert same_picture(coarse(picture(noise_seed=1)), coarse(picture(noise_seed=2)))
    for sigma in (1.0, 2.0, 4.0):
        assert same_picture(coarse(gaussian(picture(), sigma, 1)),
                            coarse(gaussian(picture(), sigma, 2)))
    assert not same_picture(coarse(picture(0)), coarse(picture(1)))


@pytest.mark.parametrize("sigma", [1.0, 2.0, 4.0])
def test_a_picture_repeated_with_fresh_noise_while_a_car_closes_is_frozen(sigma):
    decoder = FrameDecoder(W, H, logging.getLogger("test"))
    still = picture()
    stamp = feed_frames(decoder, [gaussian(still, sigma, i) for i in range(30)])
    result = decide(decoder, make_core(FixedVerifier()), stamp, CLOSING)
    assert result.targets.unavailable_reason == FROZEN_REASON
    assert result.command.decision is Decision.WARNING


def road_with_car(x_m: float) -> np.ndarray:
    return render(CAL, Scene(obstacles=(Obstacle(x_m, 0.0),), seed=3))[:, :, 1]


def test_a_live_camera_watching_a_car_close_is_never_frozen():
    # 30 km/h from 18 m to 8 m, 30 frames a second with noise: every cycle uses the camera
    decoder = FrameDecoder(CAL.width, CAL.height, logging.getLogger("test"))
    core = make_core(FixedVerifier())
    speed, t = 8.3, 0.0
    for i in range(36):
        t = i * FRAME_NS / 1e9
        x = 18.0 - speed * t
        stamp = T0 + i * FRAME_NS
        decoder.decode_now(payload(gaussian(road_with_car(x), 2.0, i), i, stamp), i)
        if i % 2:
            result = decide(decoder, core, stamp, track(x=x, vx=-speed))
            assert result.targets.verifier_status is VerifierStatus.OK, (i, x)
    assert core.frozen_cycles == {}


def test_a_far_car_closing_slowly_does_not_make_a_still_camera_frozen():
    # its column moves less than a low-pass cell in the window: a still picture is possible
    assert expected_change_px(projector(), [track(x=60.0, vx=-1.0)], 1_000 * MS) \
        < EXPECTED_CHANGE_MIN_PX
    decoder = FrameDecoder(W, H, logging.getLogger("test"))
    stamp = feed_frames(decoder, [gaussian(picture(), 2.0, i) for i in range(30)])
    result = decide(decoder, make_core(FixedVerifier()), stamp, track(x=60.0, vx=-1.0))
    assert result.targets.verifier_status is VerifierStatus.OK


def test_a_near_car_closing_at_30_kmh_moves_its_column_by_more_than_the_bound():
    for x in (8.0, 12.0, 16.0):
        assert expected_change_px(projector(), [track(x=x, vx=-8.3)], 500 * MS) \
            >= EXPECTED_CHANGE_MIN_PX, x


@pytest.mark.parametrize("noise", [False, True])
def test_a_still_picture_while_nothing_moves_is_not_frozen(noise):
    # a live camera on a standing ego in a still scene: the same picture up to noise,
    # used as before
    decoder = FrameDecoder(W, H, logging.getLogger("test"))
    stamp = feed_frames(decoder, [gaussian(picture(), 2.0, i) if noise else picture()
                                  for i in range(60)])
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
