"""Messages published by the radar service."""

import enum
from typing import TYPE_CHECKING

import msgspec

from aeb_radar_camera.common.messages.header import Header

if TYPE_CHECKING:
    import can


class OutputMode(enum.Enum):
    OBJECTS = "objects"
    CLUSTERS = "clusters"


class BusState(enum.Enum):
    ACTIVE = "active"          # frames arriving
    SILENT = "silent"          # bus open, nothing received recently
    ERROR = "error"            # bus reported errors
    REOPENING = "reopening"    # bus vanished, reopening with backoff
    ENDED = "ended"            # a finite replay reached its end


# Why a service reading a bus in each state is not ready (when ACTIVE: its own reasons).
BUS_NOT_READY = {
    BusState.SILENT: "no CAN frames received recently",
    BusState.ERROR: "CAN bus reports errors",
    BusState.REOPENING: "CAN bus lost, reopening",
    BusState.ENDED: "replay ended",
}


# The ARS408's object classes (0x60D Obj_Class), by code.
OBJECT_CLASSES = ("point", "car", "truck", "pedestrian", "motorcycle", "bicycle", "wide")


# Unlike the other messages of many fields not keyword-only: the tracker builds hundreds
# per cycle positionally, and 16 keyword arguments cost CPython about five times as much.
class RadarTrack(msgspec.Struct, frozen=True, gc=False):
    """One Kalman track in the radar frame (x forward, y left, z up; origin at the radar).

    `range_rate_mps` is the time derivative of range: negative means closing.
    """

    track_id: int
    x_m: float
    y_m: float
    vx_mps: float
    vy_mps: float
    range_m: float
    range_rate_mps: float
    rcs_dbsm: float
    confirmed: bool
    hits: int                  # consecutive updates so far
    misses: int                # consecutive cycles without an update
    x_var_m2: float
    y_var_m2: float
    radar_object_id: int = -1  # the radar's own ID in object mode, -1 when unknown
    dyn_prop: int = -1         # ARS408 dynamic property (0 moving, 1 stationary, ...), -1 unknown
    obj_class: int = -1        # ARS408 object class (0x60D: 0 point, 1 car, ...), -1 when unknown


class RadarTracks(msgspec.Struct, frozen=True, gc=False, kw_only=True):
    """Every track of one radar cycle, confirmed or not; published every cycle, also when empty.

    `header.stamp_ns` is the wall time the cycle's status frame was received.
    `last_frame_mono_ns` is the radar host's monotonic time at the cycle's last CAN frame:
    the start of the radar-to-brake latency chain.
    """

    header: Header
    sensor: str
    mode: OutputMode
    meas_counter: int
    complete: bool             # all frames announced by the status message arrived
    n_detections: int          # decoded detections in the cycle
    n_prefiltered: int         # detections left after the prefilter
    last_frame_mono_ns: int
    processing_ns: int         # from the last CAN frame to this message (decode + track left)
    tracks: tuple[RadarTrack, ...]


class RadarState(msgspec.Struct, frozen=True, gc=False, kw_only=True):
    """Decoded 0x201 RadarState."""

    nvm_read_ok: bool
    max_distance_m: int
    persistent_error: bool
    interference: bool
    temperature_error: bool
    temporary_error: bool
    voltage_error: bool
    sensor_id: int
    sort_index: int
    motion_rx_state: int
    send_ext_info: bool
    send_quality: bool
    output_type: int
    rcs_threshold: int


class RadarStatus(msgspec.Struct, frozen=True, gc=False, kw_only=True):
    """Radar health: published at 1 Hz and on every change of `ready`, `bus_state` or state."""

    header: Header
    sensor: str
    ready: bool
    not_ready_reason: str      # empty when ready
    bus_state: BusState
    interface: str             # python-can interface name, or "replay"
    channel: str
    radar_state: RadarState | None
    firmware: str              # "4.30.2", empty until 0x700 is seen
    cycle_period_ms: float     # median over recent cycles, 0 until measured
    frames_per_s: float
    cycles_total: int
    cycles_incomplete: int
    bus_reopens: int
    rejected: dict[str, int]   # frames rejected, by reason
    sensor_id: int = -1        # the radar's SensorID (CAN IDs are ID + 0x10 * sensor_id)
    meas_counter_gaps: int = 0         # cycles the radar counted that never arrived
    tracker_resets: int = 0            # gaps or time jumps that restarted the tracker
    ego_motion_frames_sent: int = 0    # 0x300 / 0x301 frames written to this radar
    # Confirmed tracks that lost their detection and took a free one near them (a
    # target that sets off sideways keeps its id and evidence: tracker `reacquire_chi2`).
    tracks_resumed: int = 0


class CanFrame(msgspec.Struct, frozen=True, gc=False, array_like=True, kw_only=True):
    """One CAN frame as the radar service received it (encoded as an array: a cycle has
    hundreds; a field added later goes at the end, with a default, so that older readers
    still decode it). `timestamp_s` is the interface's own time (python-can's `Message.timestamp`,
    the log's time in a replay); `rx_wall_ns` / `rx_mono_ns` are the host's receive times
    the service used. `flags`: CAN_EXTENDED | CAN_REMOTE | CAN_ERROR."""

    timestamp_s: float
    rx_wall_ns: int
    rx_mono_ns: int
    arb_id: int
    data: bytes
    flags: int = 0


CAN_EXTENDED = 1
CAN_REMOTE = 2
CAN_ERROR = 4


class RawCanFrames(msgspec.Struct, frozen=True, gc=False):
    """The raw frames of one CAN bus, in receive order, published when the radar is asked
    to (`[radar.raw_can] publish = true`): every frame received since the previous batch,
    one batch per radar cycle (after its tracks) and at least every cycle period while
    frames flow. `header.stamp_ns` is the first frame's receive wall time."""

    header: Header
    bus: str                   # the configured bus name, the key's parameter
    interface: str             # python-can interface name, or "replay"
    channel: str
    frames: tuple[CanFrame, ...]


def can_frame(msg: "can.Message", rx_wall_ns: int, rx_mono_ns: int) -> CanFrame:
    """A python-can message as a CanFrame, received at the given host times."""
    return CanFrame(timestamp_s=msg.timestamp, rx_wall_ns=rx_wall_ns, rx_mono_ns=rx_mono_ns,
                    arb_id=msg.arbitration_id, data=bytes(msg.data),
                    flags=(CAN_EXTENDED if msg.is_extended_id else 0)
                    | (CAN_REMOTE if msg.is_remote_frame else 0)
                    | (CAN_ERROR if msg.is_error_frame else 0))


def can_message(frame: CanFrame, timestamp_s: float | None = None) -> "can.Message":
    """A CanFrame as a python-can message, stamped `timestamp_s` (default: the
    interface's time, `frame.timestamp_s`)."""
    import can  # here: most users of the message types never touch a CAN bus

    return can.Message(timestamp=frame.timestamp_s if timestamp_s is None else timestamp_s,
                       arbitration_id=frame.arb_id, data=frame.data,
                       is_extended_id=bool(frame.flags & CAN_EXTENDED),
                       is_remote_frame=bool(frame.flags & CAN_REMOTE),
                       is_error_frame=bool(frame.flags & CAN_ERROR))
