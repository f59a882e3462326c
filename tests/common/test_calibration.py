import math

import numpy as np
import pytest

from common.calibration import Calibration, Pose, pose_to_rt
from common.config.loader import ConfigError

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
