"""Build whole ARS408 transmissions from physical values: what a radar (or the scenario
simulator, or a test) puts on the bus.

Frame order is the radar's: status, N general, then N quality and N extended when given.
"""

import math
from collections.abc import Sequence

from aeb_radar_camera.services.radar.ars408.codec import EncodeError, RadarFrame, encode
from aeb_radar_camera.services.radar.ars408.records import (
    ClusterGeneral,
    ClusterListStatus,
    ClusterQuality,
    ObjectExtended,
    ObjectGeneral,
    ObjectListStatus,
    ObjectQuality,
    SpeedInformation,
    YawRateInformation,
)

MAX_LIST = 255


def object_cycle_frames(
    objects: Sequence[ObjectGeneral],
    meas_counter: int,
    quality: Sequence[ObjectQuality] | None = None,
    extended: Sequence[ObjectExtended] | None = None,
    sensor_id: int = 0,
    interface_version: int = 1,
) -> list[RadarFrame]:
    """One object-mode cycle: 0x60A, then 0x60B per object, then 0x60C / 0x60D if given.

    `meas_counter` wraps at 65536. Raises EncodeError for more than 255 objects or
    unrepresentable values, ValueError when quality/extended lists differ in length.
    """
    if len(objects) > MAX_LIST:
        raise EncodeError(f"{len(objects)} objects: the status message counts at most 255")
    for name, extra in (("quality", quality), ("extended", extended)):
        if extra is not None and len(extra) != len(objects):
            raise ValueError(f"{len(extra)} {name} records for {len(objects)} objects")
    status = ObjectListStatus(len(objects), meas_counter % 65536, interface_version)
    frames = [encode(status, sensor_id)]
    frames += [encode(o, sensor_id) for o in objects]
    frames += [encode(q, sensor_id) for q in quality or ()]
    frames += [encode(e, sensor_id) for e in extended or ()]
    return frames


def cluster_cycle_frames(
    clusters: Sequence[ClusterGeneral],
    meas_counter: int,
    quality: Sequence[ClusterQuality] | None = None,
    n_near: int | None = None,
    sensor_id: int = 0,
    interface_version: int = 1,
) -> list[RadarFrame]:
    """One cluster-mode cycle: 0x600, then 0x701 per cluster, then 0x702 if given.

    The first `n_near` clusters are near-scan ones (all of them when None). Raises
    EncodeError for counts that do not fit a byte, ValueError on mismatched lengths.
    """
    near = len(clusters) if n_near is None else n_near
    far = len(clusters) - near
    if not (0 <= near <= MAX_LIST and 0 <= far <= MAX_LIST):
        raise EncodeError(f"near={near} far={far}: each count must fit 0..255")
    if quality is not None and len(quality) != len(clusters):
        raise ValueError(f"{len(quality)} quality records for {len(clusters)} clusters")
    status = ClusterListStatus(near, far, meas_counter % 65536, interface_version)
    frames = [encode(status, sensor_id)]
    frames += [encode(c, sensor_id) for c in clusters]
    frames += [encode(q, sensor_id) for q in quality or ()]
    return frames


SPEED_STEP_MPS = 0.02
STANDSTILL = 0
FORWARD = 1
REVERSE = 2


def ego_motion_frames(speed_mps: float, yaw_rate_dps: float,
                      sensor_id: int = 0) -> list[RadarFrame]:
    """0x300 and 0x301 for an ego speed (negative = reversing) and yaw rate (left positive).

    A speed that rounds to zero steps is sent as standstill. Raises EncodeError when a
    value is outside the radar's range (speed above 163.8 m/s, |yaw| above 327 deg/s, NaN
    or infinite).
    """
    magnitude = abs(speed_mps)
    steps = magnitude / SPEED_STEP_MPS
    if not math.isfinite(steps):     # round() would raise ValueError / OverflowError
        raise EncodeError(f"speed {speed_mps} m/s is outside the radar's range")
    direction = STANDSTILL if round(steps) == 0 else FORWARD if speed_mps > 0 else REVERSE
    return [
        encode(SpeedInformation(direction, magnitude), sensor_id),
        encode(YawRateInformation(yaw_rate_dps), sensor_id),
    ]
