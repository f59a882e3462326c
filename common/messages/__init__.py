"""Every message type on the bus. Defined here and nowhere else."""

from common.messages.brake import BrakeState, BrakeStatus, FailsafePolicy
from common.messages.camera import CameraInfo, CompressedFrame, DepthFrame
from common.messages.codec import DecodeError, decode, encode
from common.messages.fusion import (
    BrakeCommand,
    CommandAuth,
    Decision,
    Verification,
    VerifiedTarget,
    VerifiedTargets,
    VerifierStatus,
)
from common.messages.header import SCHEMA_VERSION, Header
from common.messages.radar import (
    BusState,
    CanFrame,
    OutputMode,
    RadarState,
    RadarStatus,
    RadarTrack,
    RadarTracks,
    RawCanFrames,
)
from common.messages.vehicle import DriverInputs, EgoMotion, Gear, SignalHealth, VehicleStatus

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
