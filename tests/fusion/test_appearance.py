"""The appearance verifiers: the HOG equals OpenCV 4's, OpenCV's pedestrian detector
responds to a person's shape, hog_linear loads its weights (and refuses bad ones) and
separates what it was trained on, and the combined verifier says which cue decided."""

import json
from collections.abc import Mapping
from pathlib import Path

import cv2
import numpy as np
import pytest

from aeb_radar_camera.services.fusion.roi import Roi
from aeb_radar_camera.services.fusion.verifiers import (
    _REGISTRY,
    GateResult,
    Observation,
    ParamValue,
    Verifier,
    VerifierConfigError,
    create,
    hog,
)
from aeb_radar_camera.services.fusion.verifiers.appearance import (
    HOG_LINEAR_FORMAT,
    HogLinearModel,
    hog_linear_features,
    people_detector,
    window_around,
)
from aeb_radar_camera.tools.eval.scoring import default_specs
from aeb_radar_camera.tools.eval.train_verifier import fit_logistic
from tests.fusion.helpers import CAL
from tests.fusion.test_depth_check import WIDE, observe, render_depth

REFERENCE = Path(__file__).parent.parent / "data" / "hog_reference.json"


def test_hog_equals_opencv4s_descriptor():
    ref = json.loads(REFERENCE.read_text())
    image = np.array(ref["image"], np.uint8)
    got = hog.descriptor(image)
    assert got.shape == (len(ref["descriptor"]),)
    np.testing.assert_allclose(got, ref["descriptor"], atol=1e-5)


def test_window_scores_are_the_descriptor_of_each_window_dotted():
    rng = np.random.default_rng(3)
    image = cv2.GaussianBlur(rng.integers(0, 256, (80, 56), dtype=np.uint8), (3, 3), 1)
    weights = rng.normal(size=3 * 7 * 36).astype(np.float32)
    scores = hog.window_scores(hog.block_grid(image), weights, 0.5, (3, 7))
    assert scores.shape == (((80 - 64) // 8) + 1, ((56 - 32) // 8) + 1)
    for iy, ix in [(0, 0), (2, 3), (1, 2)]:
        window = image[iy * 8:iy * 8 + 64, ix * 8:ix * 8 + 32]
        # Gradients at a window's border see the neighbours in the image, not a mirror:
        # compare with the blocks of the whole image's grid.
        grid = hog.block_grid(image)[ix:ix + 3, iy:iy + 7].ravel()
        assert scores[iy, ix] == pytest.approx(float(grid @ weights) + 0.5, rel=1e-4)
        assert window.shape == (64, 32)
    with pytest.raises(ValueError, match="holds no"):
        hog.window_scores(hog.block_grid(image[:32, :32]), weights, 0.0, (3, 7))
    with pytest.raises(ValueError, match="uint8"):
        hog.descriptor(np.zeros((64, 32), np.float32))


def person(shape: tuple[int, int], cx: int, foot: int, height: int) -> np.ndarray:
    """A dark figure (head, torso, arms, legs) on a mid-grey background."""
    img = np.full(shape, 170, np.uint8)
    u = height / 8.0
    head = (cx, int(foot - 7.4 * u))
    cv2.circle(img, head, int(0.55 * u), 40, -1)
    cv2.rectangle(img, (int(cx - 0.9 * u), int(foot - 6.8 * u)),
                  (int(cx + 0.9 * u), int(foot - 3.8 * u)), 40, -1)
    for side in (-1, 1):
        cv2.line(img, (int(cx + side * 0.9 * u), int(foot - 6.6 * u)),
                 (int(cx + side * 1.3 * u), int(foot - 4.0 * u)), 40, max(1, int(0.4 * u)))
        cv2.line(img, (int(cx + side * 0.4 * u), int(foot - 3.8 * u)),
                 (int(cx + side * 0.7 * u), foot), 40, max(1, int(0.5 * u)))
    return cv2.GaussianBlur(img, (3, 3), 0)


def test_hog_people_scores_a_person_above_an_empty_column_and_a_wall():
    v = create("hog_people")
    shape = (240, 320)
    column = Roi(140, 40, 40, 160)             # 2.2 m tall; the person 1.75 m of it
    roi = Roi(118, 18, 84, 204)
    foot = column.y + column.h
    standing = person(shape, 160, foot, int(column.h * 1.75 / 2.2))
    empty = np.full(shape, 170, np.uint8)
    bricks = np.full(shape, 170, np.uint8)
    for y in range(0, shape[0], 12):
        cv2.line(bricks, (0, y), (shape[1], y), 60, 2)
    scores = {name: v.verify(Observation(img, roi, column, 8.0)).score
              for name, img in (("person", standing), ("empty", empty), ("bricks", bricks))}
    assert scores["person"] > scores["empty"] + 1.0
    assert scores["person"] > scores["bricks"] + 1.0
    assert v.verify(Observation(standing, roi, column, 8.0)).verified
    w, b = people_detector()
    assert w.shape == (3780,) and np.isfinite(b)


def test_a_window_beyond_the_frame_is_filled_from_its_border():
    gray = np.tile(np.arange(100, dtype=np.uint8), (50, 1))
    win = window_around(gray, 5.0, 25.0, 1.0, (32, 16))
    assert win.shape == (16, 32)
    assert (win[:, :11] == 0).all() and win[0, -1] == 20


def bars(vertical: bool, rng: np.random.Generator) -> np.ndarray:
    img = rng.integers(90, 110, (120, 200)).astype(np.uint8)
    for k in range(6):
        p = 10 + 30 * k + int(rng.integers(0, 8))
        if vertical:
            cv2.rectangle(img, (70 + k * 6, 20), (72 + k * 6, 100), 20, -1)
        else:
            cv2.line(img, (0, p // 2 + 10), (200, p // 2 + 10), 200, 2)
    return img


COLUMN = Roi(80, 20, 40, 80)
ROI = Roi(58, 0, 84, 120)


def synthetic_model(tmp_path: Path, tau: float = 0.5) -> Path:
    rng = np.random.default_rng(5)
    x, y = [], []
    for i in range(40):
        img = bars(i % 2 == 0, rng)
        x.append(hog_linear_features(Observation(img, ROI, COLUMN, 10.0), (32, 64), 1.25))
        y.append(1.0 if i % 2 == 0 else 0.0)
    coef, bias = fit_logistic(np.array(x, np.float64), np.array(y), l2=10.0)
    path = tmp_path / "w.json"
    HogLinearModel((32, 64), 1.25, coef.astype(np.float32), bias, tau,
                   {"frames": ["synthetic"]}).save(path)
    return path


def test_hog_linear_separates_what_it_was_trained_on(tmp_path):
    path = synthetic_model(tmp_path)
    v = create("hog_linear", {"weights": str(path)})
    assert v.params() == {"weights": str(path), "tau": 0.5}
    rng = np.random.default_rng(99)                 # images it has not seen
    yes = [v.verify(Observation(bars(True, rng), ROI, COLUMN, 10.0)) for _ in range(5)]
    no = [v.verify(Observation(bars(False, rng), ROI, COLUMN, 10.0)) for _ in range(5)]
    assert all(r.verified and r.score > 0.9 for r in yes)
    assert not any(r.verified or r.score > 0.1 for r in no)
    v2 = create("hog_linear", {"weights": str(path), "tau": 0.999})
    assert v2.params()["tau"] == 0.999


def test_hog_linear_refuses_missing_or_bad_weights(tmp_path):
    with pytest.raises(VerifierConfigError, match=r"needs params\.weights"):
        create("hog_linear")
    with pytest.raises(VerifierConfigError, match="No such file"):
        create("hog_linear", {"weights": str(tmp_path / "none.json")})
    good = json.loads(synthetic_model(tmp_path).read_text())
    for change, match in (({"format": "other"}, "format"),
                          ({"coef": good["coef"][:-1]}, "coefficients"),
                          ({"window": [30, 64]}, "multiples"),
                          ({"tau": "x"}, "could not convert")):
        bad = tmp_path / "bad.json"
        bad.write_text(json.dumps({**good, **change}))
        with pytest.raises(VerifierConfigError, match=match):
            create("hog_linear", {"weights": str(bad)})
    (tmp_path / "junk.json").write_text("{")
    with pytest.raises(VerifierConfigError, match=r"junk\.json"):
        create("hog_linear", {"weights": str(tmp_path / "junk.json")})
    assert good["format"] == HOG_LINEAR_FORMAT
    # `aeb eval` scores every verifier that works with its defaults; hog_linear needs a file.
    names = [s.name for s in default_specs()]
    assert "hog_people" in names and "hog_linear" not in names and "combined" not in names


def fake_look(params: Mapping[str, ParamValue]) -> Verifier:
    """An appearance cue whose score is the mean grey of the column, threshold 0.5."""

    class Look:
        name = "hog_linear"
        needs_depth = False

        def params(self) -> dict[str, ParamValue]:
            return {"weights": str(params.get("weights", "")), "tau": 0.5}

        def verify(self, obs: Observation) -> GateResult:
            c = obs.column
            s = float(obs.gray[c.y:c.y + c.h, c.x:c.x + c.w].mean()) / 255.0
            return GateResult(s, s >= 0.5)

    return Look()


def test_combined_needs_both_cues_and_says_which_decided(monkeypatch):
    monkeypatch.setitem(_REGISTRY, "hog_linear", fake_look)
    v = create("combined", {"weights": "fake.json"})
    car = render_depth(CAL, boxes=((10.0, 12.0, -0.8, 0.8, 0.0, 1.5),))
    road = render_depth(CAL)
    at_car = observe(car, 10.0, projector=WIDE)
    bright = np.full_like(at_car.gray, 230)     # looks like an obstacle (ratio 1.8)
    dark = np.full_like(at_car.gray, 64)        # does not (ratio 0.5)

    def look(obs: Observation, gray: np.ndarray, depth: np.ndarray | None) -> GateResult:
        return v.verify(Observation(gray, obs.roi, obs.column, obs.range_m, depth,
                                    obs.calibration, obs.xy_m))

    both = look(at_car, bright, car)
    assert both.verified and both.detail["depth_available"] == 1.0
    assert both.detail["depth_ratio"] >= 1.0
    assert both.score == pytest.approx(both.detail["appearance_ratio"])
    wall_like = look(at_car, dark, car)         # something stands there; not an obstacle
    assert not wall_like.verified and wall_like.detail["decided_appearance"] == 1.0
    empty = look(at_car, bright, road)          # looks fine; nothing stands at the range
    assert not empty.verified and empty.detail["decided_depth"] == 1.0
    assert empty.score == pytest.approx(0.0) and "appearance" not in empty.detail
    no_depth = look(at_car, bright, None)       # a camera without depth
    assert no_depth.verified and no_depth.detail["depth_available"] == 0.0
    assert no_depth.score == pytest.approx(230 / 255 / 0.5)
    # One threshold: raised, the same obstacle no longer passes.
    strict = create("combined", {"weights": "fake.json", "tau": 2.0})
    assert not strict.verify(Observation(bright, at_car.roi, at_car.column, at_car.range_m,
                                         car, at_car.calibration, at_car.xy_m)).verified
    assert v.params()["appearance_tau"] == 0.5


def test_combined_refuses_bad_params():
    with pytest.raises(VerifierConfigError, match="appearance"):
        create("combined", {"appearance": "edges"})
    with pytest.raises(VerifierConfigError, match="no cue"):
        create("combined", {"appearance": "none", "use_depth": False})
    with pytest.raises(VerifierConfigError, match="weights"):
        create("combined")
    depth_only = create("combined", {"appearance": "none"})
    assert not depth_only.verify(Observation(np.zeros((10, 10), np.uint8), Roi(0, 0, 5, 5),
                                             Roi(1, 1, 2, 2), 5.0)).verified


def test_in_fusion_the_combined_verifier_gets_depth_when_the_camera_has_it(monkeypatch):
    import logging

    from aeb_radar_camera.common.messages import VerifierStatus
    from aeb_radar_camera.services.fusion.frames import FrameDecoder
    from aeb_radar_camera.services.fusion.shell import FusionShell
    from tests.fusion.helpers import feed, make_core, run, track
    from tests.fusion.test_depth_check import car
    from tests.fusion.test_depth_fusion import SubscribingBus, with_depth

    monkeypatch.setitem(_REGISTRY, "hog_linear", fake_look)
    spec = {"name": "combined", "params": {"weights": "fake.json"}}
    t = track(x=10.0, vx=-8.0)
    with_car = with_depth(render_depth(CAL, boxes=(car(10.0),)))
    got = run(make_core(verifier=spec), t, frames=feed(with_car))
    detail = got.targets.targets[0].gate_detail
    assert detail["depth_available"] == 1.0 and "depth_ratio" in detail
    # A frame without depth: still usable, appearance alone decides and says so.
    got = run(make_core(verifier=spec), t, frames=feed(with_depth(None)))
    assert got.targets.verifier_status is VerifierStatus.OK
    assert got.targets.targets[0].gate_detail["depth_available"] == 0.0
    # The shell subscribes to depth for it (it uses depth without needing it).
    bus = SubscribingBus()
    core = make_core(verifier=spec)
    dec = FrameDecoder(CAL.width, CAL.height, logging.getLogger("test"))
    shell = FusionShell(bus, core.s, core, dec, logging.getLogger("test"))  # type: ignore[arg-type]
    shell.start()
    try:
        assert bus.subs["camera_depth"] == dec.submit_depth
    finally:
        shell.stop()


def test_combined_prepares_its_depth_cue_for_each_camera(monkeypatch):
    import aeb_radar_camera.services.fusion.verifiers.depth as depth_check

    monkeypatch.setitem(_REGISTRY, "hog_linear", fake_look)
    seen = []
    monkeypatch.setattr(depth_check, "ray_maps", lambda cal: seen.append(cal))
    v = create("combined", {"weights": "fake.json"})
    v.prepare(CAL)  # type: ignore[attr-defined]
    assert seen == [CAL]
