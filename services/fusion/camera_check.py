"""Does the camera publish the calibration fusion uses? (pure)

Fusion projects with its own calibration file (it may run on another board than the
camera); the camera publishes the one it was given in CameraInfo. After a recalibration
the two can diverge silently, and every ROI would be off. Fusion compares each CameraInfo
with its file and warns, naming what differs; it does not switch calibrations by itself.
"""

import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.messages import CameraInfo

_TOL = 1e-6


def calibration_differences(cal: Calibration, info: CameraInfo) -> list[str]:
    """What differs between fusion's calibration and the camera's (empty: the same)."""
    out = []
    if (info.width, info.height) != (cal.width, cal.height):
        out.append(f"size {info.width}x{info.height} != {cal.width}x{cal.height}")
    pairs = (("K", info.k, cal.k), ("R", info.r, cal.r), ("t", info.t_m, cal.t))
    for name, theirs, ours in pairs:
        if np.size(theirs) != np.size(ours) or not np.allclose(
                np.ravel(theirs), np.ravel(ours), rtol=_TOL, atol=_TOL):
            out.append(f"{name} differs")
    theirs_d = np.trim_zeros(np.asarray(info.dist, float), "b")
    ours_d = np.trim_zeros(np.asarray(cal.dist, float), "b")
    if len(theirs_d) != len(ours_d) or not np.allclose(theirs_d, ours_d, atol=_TOL):
        out.append("distortion differs")
    return out
