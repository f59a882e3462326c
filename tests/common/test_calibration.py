import math

import numpy as np
import pytest

from aeb_radar_camera.common.calibration import Calibration, Pose, pose_to_rt
from aeb_radar_camera.common.config.loader import ConfigError

REPO_CAL = "deploy/calibration/d435_848x480.toml"


def test_example_calibration_loads_and_projects_a_point_ahead_to_the_centre_column():
    cal = Calibration.load(REPO_CAL)
    # A point 10 m ahead at the camera's height lies on the optical axis.
    uv, ok = cal.project(np.array([[10.0, 0.0, 1.3]]))
    assert ok.all()
    assert uv[0] == pytest.approx([424.0, 240.0])


def test_hand_computed_projection_with_pose():
    cal = Calibration.load(REPO_CAL)
    # Ground point 9.2 m ahead of the radar (10 m ahead of the camera), 1 m to the left.
    uv, _ = cal.project(np.array([[9.2, 1.0, 0.0]]))
    # x_cam = -1 (left), y_cam = +1.3 (down), z = 10: u = 424 - 61.5, v = 240 + 79.95
    assert uv[0] == pytest.approx([424.0 - 61.5, 240.0 + 79.95])


def test_points_behind_the_camera_are_not_projected():
    cal = Calibration.load(REPO_CAL)
    uv, ok = cal.project(np.array([[-2.0, 0.0, 1.0], [5.0, 0.0, 1.0]]))
    assert ok.tolist() == [False, True]
    assert np.isnan(uv[0]).all()


def test_pitch_down_moves_the_horizon_up():
    r, t = pose_to_rt(Pose(position_m=(0.0, 0.0, 1.0), pitch_deg=5.0))
    far = r @ np.array([1000.0, 0.0, 1.0]) + t
    assert far[1] / far[2] == pytest.approx(-math.tan(math.radians(5.0)), rel=1e-3)


def test_distortion_matches_hand_computed_radial_model():
    cal = Calibration.from_matrices(
        848, 480, np.array([[600.0, 0, 424], [0, 600.0, 240], [0, 0, 1]]),
        np.array([0.1, 0.0, 0.0, 0.0, 0.0]), np.eye(3), np.zeros(3))
    # Camera-frame point (1, 0.5, 5): x = 0.2, y = 0.1, r2 = 0.05, factor 1.005
    uv, _ = cal.project(np.array([[1.0, 0.5, 5.0]]))
    assert uv[0] == pytest.approx([424 + 600 * 0.2 * 1.005, 240 + 600 * 0.1 * 1.005])


@pytest.mark.parametrize(
    ("camera", "extr", "named"),
    [
        ("fx = -1.0", "", "$.camera.fx"),
        ("cx = 900.0", "", "principal point"),
        ("distortion = [0.1, 0.2, 0.3]", "", "distortion has 3"),
        ("", "r = [[1,0,0],[0,1,0],[0,0.5,1]]\nt_m = [0,0,0]", "not orthonormal"),
        ("", "r = [[1,0,0],[0,1,0],[0,0,-1]]\nt_m = [0,0,0]", "reflection"),
        ("", "r = [[1,0,0],[0,1,0],[0,0,1]]", "needs `t_m`"),
        ("", "", "either `pose`"),
    ],
)
def test_invalid_calibration_names_the_problem(tmp_path, camera, extr, named):
    base = {"fx": "600.0", "fy": "600.0", "cx": "424.0", "cy": "240.0"}
    lines = ["[camera]", "width = 848", "height = 480"]
    override = dict(line.split(" = ", 1) for line in [camera] if line)
    lines += [f"{k} = {override.pop(k, v)}" for k, v in base.items()]
    lines += [f"{k} = {v}" for k, v in override.items()]
    lines += ["[extrinsics]", extr]
    p = tmp_path / "cal.toml"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConfigError) as err:
        Calibration.load(p)
    assert named in str(err.value)


def write_cal(tmp_path, camera: str = "", extrinsics: str = "") -> str:
    p = tmp_path / "cal.toml"
    p.write_text("[camera]\nwidth = 848\nheight = 480\n"
                 + (camera or "fx = 615.0\nfy = 615.0\ncx = 424.0\ncy = 240.0\n")
                 + "[extrinsics.pose]\n"
                 + (extrinsics or "position_m = [-0.8, 0.0, 1.3]\n"))
    return str(p)


@pytest.mark.parametrize(
    ("camera", "extrinsics", "named"),
    [
        # A focal length in millimetres (the D435's 1.93 mm) instead of pixels.
        ("fx = 1.93\nfy = 1.93\ncx = 424.0\ncy = 240.0\n", "", "focal lengths are in pixels"),
        ("fx = 615.0\nfy = 615.0\ncx = 424.0\ncy = 240.0\ndistortion = [0.0, nan, 0.0, 0.0]\n",
         "", "`camera` has a value that is not a finite number"),
        ("", "position_m = [0.0, inf, 1.3]\n", "`pose` has a value that is not a finite"),
        ("", "position_m = [0.0, 0.0, 1.3]\npitch_deg = 90.0\n", "$.extrinsics.pose.pitch_deg"),
        ("", "position_m = [0.0, 0.0, 1.3]\nyaw_deg = 270.0\n", "$.extrinsics.pose.yaw_deg"),
    ],
)
def test_unit_and_range_mistakes_are_rejected(tmp_path, camera, extrinsics, named):
    with pytest.raises(ConfigError) as err:
        Calibration.load(write_cal(tmp_path, camera, extrinsics))
    assert named in str(err.value)


def test_example_is_plausible_and_its_camera_sits_where_the_pose_says():
    cal = Calibration.load(REPO_CAL)
    assert cal.warnings() == []
    np.testing.assert_allclose(cal.camera_position_m, [-0.8, 0.0, 1.3], atol=1e-12)
    # D435 colour at 848x480: about 69 x 42 degrees.
    assert math.degrees(2 * math.atan(424 / cal.k[0, 0])) == pytest.approx(69.2, abs=0.1)


def test_warnings_catch_an_inverted_rotation_and_a_translation_in_millimetres(tmp_path):
    good = Calibration.load(REPO_CAL)
    # R given camera-to-radar (transposed) instead of radar-to-camera.
    inverted = Calibration.from_matrices(848, 480, good.k, good.dist, good.r.T, good.t)
    assert any("is R inverted" in w for w in inverted.warnings())
    in_mm = Calibration.from_matrices(848, 480, good.k, good.dist, good.r, good.t * 1000)
    assert any("wrong frame or unit" in w for w in in_mm.warnings())
    pitched = Calibration.load(write_cal(
        tmp_path, "", "position_m = [0.0, 0.0, 1.3]\npitch_deg = 45.0\n"))
    assert pitched.warnings() == ["the camera is pitched 45 deg (positive: down)"]


def test_the_documented_r_and_t_equal_the_example_pose(tmp_path):
    """docs/calibration.md shows both forms of the example; they must agree."""
    p = tmp_path / "cal.toml"
    p.write_text("[camera]\nwidth = 848\nheight = 480\nfx = 615.0\nfy = 615.0\n"
                 "cx = 424.0\ncy = 240.0\n[extrinsics]\n"
                 "r = [[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]\n"
                 "t_m = [0.0, 1.3, 0.8]\n")
    matrices, pose = Calibration.load(p), Calibration.load(REPO_CAL)
    np.testing.assert_allclose(matrices.r, pose.r, atol=1e-12)
    np.testing.assert_allclose(matrices.t, pose.t, atol=1e-12)
