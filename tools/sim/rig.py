"""SIMULATION: a camera rig for multi-camera tests and benchmarks: the example D435
intrinsics (848x480), cameras 1.3 m up; front (the example calibration's pose), two
corner cameras turned 55 degrees, and a narrow front camera (twice the focal length)."""

RIG: dict[str, tuple[float, tuple[float, float, float], float]] = {
    # name: (yaw_deg, position_m, focal length px)
    "front": (0.0, (-0.8, 0.0, 1.3), 615.0),
    "left": (55.0, (-0.6, 0.7, 1.3), 615.0),
    "right": (-55.0, (-0.6, -0.7, 1.3), 615.0),
    "narrow": (0.0, (-0.8, 0.1, 1.3), 1230.0),
}


def rig_calibration_toml(name: str) -> str:
    """One RIG camera as a calibration TOML (common/calibration.py format)."""
    yaw, (px, py, pz), f = RIG[name]
    return f'''name = "synthetic-rig-{name}"
[camera]
width = 848
height = 480
fx = {f}
fy = {f}
cx = 424.0
cy = 240.0
distortion = [0.0, 0.0, 0.0, 0.0, 0.0]
[extrinsics.pose]
position_m = [{px}, {py}, {pz}]
yaw_deg = {yaw}
'''
