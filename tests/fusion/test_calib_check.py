"""`aeb calib-check` draws fusion's own ROIs over a frame and reports the densities."""

import cv2
import numpy as np
import pytest

from aeb_radar_camera.common.imaging import decode_gray, encode_jpeg
from aeb_radar_camera.common.messages import encode
from aeb_radar_camera.services.fusion.roi import Roi
from aeb_radar_camera.services.fusion.verifiers import create
from aeb_radar_camera.tools.calib import check as calib_check
from aeb_radar_camera.tools.sim.scenes import Obstacle, Scene, render
from tests.fusion.helpers import CAL, CALIBRATION, cycle, observe, track


@pytest.fixture(scope="module")
def scene_jpeg(tmp_path_factory):
    path = tmp_path_factory.mktemp("calib") / "frame.jpg"
    path.write_bytes(encode_jpeg(render(CAL, Scene(obstacles=(Obstacle(8, 0.8),),
                                                   seed=4)), 80))
    return path


def test_draws_rois_and_prints_the_densities_fusion_would_compute(scene_jpeg, tmp_path, capsys):
    out = tmp_path / "check.png"
    rc = calib_check.main(["--calibration", CALIBRATION, "--image", str(scene_jpeg),
                           "--track", "8,0.8", "--track", "6,-0.5", "--track", "5,20",
                           "--out", str(out)])
    assert rc == 0
    text = capsys.readouterr().out
    rows = {line.split()[0]: line for line in text.splitlines() if line[:1].isdigit()}
    assert "346,155,45,199" in rows["1"] and rows["1"].endswith("verified")
    assert rows["2"].endswith("rejected") and "not visible" in rows["3"]
    gray = decode_gray(scene_jpeg.read_bytes())
    density = create("edge_density").verify(observe(gray, Roi(346, 155, 45, 199))).score
    assert f"{density:.4f}" in rows["1"]
    drawn = cv2.imread(str(out))
    assert drawn is not None
    assert drawn.shape == (480, 848, 3)
    # The verified ROI's border is green, the rejected one's red (BGR).
    assert tuple(drawn[155, 360]) == calib_check._GREEN
    assert tuple(drawn[137, 460]) == calib_check._RED


def test_reads_a_recorded_cycle_and_uses_a_fusion_config(scene_jpeg, tmp_path, capsys):
    rec = tmp_path / "cycle.msgpack"
    rec.write_bytes(encode(cycle(track(7, 8.0, 0.8), track(8, 6.0, -0.5, confirmed=False))))
    cfg = tmp_path / "fusion.toml"
    cfg.write_text("[fusion.roi]\npadding_px = 10\n[fusion.verifier]\nname = 'edge_density'\n"
                   "params = { tau = 0.5 }\n")
    rc = calib_check.main(["--calibration", CALIBRATION, "--image", str(scene_jpeg),
                           "--tracks", str(rec), "--fusion-config", str(cfg),
                           "--out", str(tmp_path / "c.png")])
    assert rc == 0
    text = capsys.readouterr().out
    assert "358,167,21,175" in text                 # 10 px padding
    assert "rejected" in text and "unconfirmed" in text   # tau 0.5 rejects everything


def small_jpeg(tmp_path):
    path = tmp_path / "small.jpg"
    path.write_bytes(encode_jpeg(np.zeros((240, 424, 3), np.uint8)))
    return path


@pytest.mark.parametrize(("image", "args", "message"), [
    ("scene", ["--track", "8"], "expected X,Y"),
    ("scene", ["--tracks", "missing.msgpack"], "cannot read"),
    ("small", ["--track", "8,0"], "expected 848x480"),
])
def test_bad_input_exits_2_with_a_message(scene_jpeg, tmp_path, capsys, image, args, message):
    picture = scene_jpeg if image == "scene" else small_jpeg(tmp_path)
    rc = calib_check.main(["--calibration", CALIBRATION, "--image", str(picture),
                           "--out", str(tmp_path / "x.png"), *args])
    assert rc == 2
    assert message in capsys.readouterr().err
