"""Every message type on the bus. Defined here and nowhere else.

Every message struct is declared ``gc=False``: a message is a tree (frozen, no reference
cycles), and a process that keeps thousands of them (a monitor's history, the fault
harness's observer, a recording's index) would otherwise have the garbage collector walk
each one in every full collection, a pause that holds the GIL for every thread of the
process (`python -m benchmarks.bench_gc`: 4,000 each of four message types kept, a full
collection 1.9 ms p50 as untracked structs, 69.4 ms as the same history tracked)."""

from aeb_radar_camera.common.messages.brake import BrakeState, BrakeStatus, FailsafePolicy
from aeb_radar_camera.common.messages.camera import CameraInfo, CompressedFrame, DepthFrame
from aeb_radar_camera.common.messages.codec import DecodeError, decode, encode
from aeb_radar_camera.common.messages.fusion import (
    BrakeCommand,
    CommandAuth,
    Decision,
    Verification,
    VerifiedTarget,
    VerifiedTargets,
    VerifierStatus,
)
from aeb_radar_camera.common.messages.header import SCHEMA_VERSION, Header
from aeb_radar_camera.common.messages.radar import (
    BusState,
    CanFrame,
    OutputMode,
    RadarState,
    RadarStatus,
    RadarTrack,
    RadarTracks,
    RawCanFrames,
)
from aeb_radar_camera.common.messages.vehicle import (
    DriverInputs,
    EgoMotion,
    Gear,
    SignalHealth,
    VehicleStatus,
)

__all__ = [
    "SCHEMA_VERSION",
    "BrakeCommand",
    "BrakeState",
    "BrakeStatus",
    "BusState",
    "CameraInfo",
    "CanFrame",
    "CommandAuth",
    "CompressedFrame",
    "Decision",
    "DecodeError",
    "DepthFrame",
    "DriverInputs",
    "EgoMotion",
    "FailsafePolicy",
    "Gear",
    "Header",
    "OutputMode",
    "RadarState",
    "RadarStatus",
    "RadarTrack",
    "RadarTracks",
    "RawCanFrames",
    "SignalHealth",
    "VehicleStatus",
    "Verification",
    "VerifiedTarget",
    "VerifiedTargets",
    "VerifierStatus",
    "decode",
    "encode",
]
