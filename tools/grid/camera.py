"""The camera in lockstep: the simulated camera's frames at its rate on the simulated
clock, each rendered only when fusion first reads it. A SIMULATION of the camera.

At each capture the world is kept (as `sim/world` carries it); the frame goes into
fusion's frame source (tools/recording/frame_source.py) at the time it would reach
fusion. When fusion's code first reads its pixels, the simulator's camera source
(tools/sim/camera_source.py, the camera service's synthetic plugin) renders it from that
world, the frame is JPEG-encoded as the camera service does (common/imaging.py at the
camera's quality, a CompressedFrame with its CRC-32, encoded as on the wire) and decoded
on fusion's own path (`decode_frame`). Its depth likewise, when the verifier uses depth:
decimated and coded as the camera service publishes it (common/depth_image.py, a
DepthFrame) and decoded by fusion's `decode_depth_frame`. Frames fusion never reads are
never rendered.
"""

from dataclasses import dataclass, field

import msgspec
import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.config.camera import DepthSettings
from aeb_radar_camera.common.depth_image import encode_depth
from aeb_radar_camera.common.imaging import encode_jpeg, jpeg_crc32
from aeb_radar_camera.common.messages import CompressedFrame, DepthFrame, Header, encode
from aeb_radar_camera.services.fusion.frames import decode_depth_frame
from aeb_radar_camera.tools.grid.profile import Profile
from aeb_radar_camera.tools.messages import SimWorld
from aeb_radar_camera.tools.recording.frame_source import FrameSource, RecordedJpeg
from aeb_radar_camera.tools.sim.camera_source import SimCameraSource

# The camera source keeps only a world newer than the one it has: each frame's world is
# shown to it at a time of its own that only grows (whatever order frames are rendered
# in, across runs too), the capture stamp moved with it (only their difference counts).
_SHOW_STEP_NS = 1_000_000_000_000


class SceneCamera:
    """The simulator's camera source, rendering frames of any world on request. One per
    process and calibration (its renderer takes a second or two to build); `scene()`
    starts each run (a new scene: textures and noise from the run's seed)."""

    def __init__(self, calibration: Calibration) -> None:
        self.cal = calibration
        self.source = SimCameraSource(calibration, fps=30.0, subscribe=None,
                                      clock=lambda: 0.0, depth=True)
        self._scenes = 0
        self._shown_ns = 0

    def scene(self) -> int:
        """A number for the next run's worlds (`SimWorld.run`)."""
        self._scenes += 1
        return self._scenes

    def render(self, world: SimWorld, stamp_ns: int, depth: bool
               ) -> tuple[np.ndarray, np.ndarray | None]:
        """The BGR frame (and, with `depth`, its uint16 mm depth) of `world` captured at
        `stamp_ns` (the world's own stamp is earlier: it is extrapolated)."""
        self._shown_ns += _SHOW_STEP_NS
        shift = self._shown_ns - world.header.stamp_ns
        shown = msgspec.structs.replace(world, header=msgspec.structs.replace(
            world.header, stamp_ns=self._shown_ns))
        self.source.on_world(shown)
        if depth:
            return self.source.frame_and_depth_at(stamp_ns + shift)
        return self.source.frame_at(stamp_ns + shift), None


@dataclass(frozen=True)
class CameraSettings:
    """What the demo's camera runs with (tools/sim/stack.py writes it)."""

    name: str = "front"
    fps: float = 30.0
    jpeg_quality: int = 80
    depth: DepthSettings = field(default_factory=DepthSettings)


class CapturedFrame:
    """One capture: its world, rendered and encoded when first needed (then only the
    encoded messages are kept, as a recording would hold them)."""

    def __init__(self, camera: "LockstepCamera", world: SimWorld, seq: int, stamp_ns: int,
                 rx_mono_ns: int) -> None:
        self.camera = camera
        self.world = world
        self.seq = seq
        self.stamp_ns = stamp_ns
        self.rx_mono_ns = rx_mono_ns
        self._jpeg: bytes | None = None
        self._depth: bytes | None = None

    def _produce(self) -> None:
        cam = self.camera
        p = cam.profile
        with p.part("render"):
            image, depth = cam.scenes.render(self.world, self.stamp_ns, cam.with_depth)
        p.frames_rendered += 1
        s = cam.settings
        header = Header(seq=self.seq, source=f"camera/{s.name}", stamp_ns=self.stamp_ns,
                        pub_mono_ns=self.rx_mono_ns)
        with p.part("jpeg_encode"):
            jpeg = encode_jpeg(image, s.jpeg_quality)
            self._jpeg = encode(CompressedFrame(
                header=header, camera=s.name, width=cam.width, height=cam.height, jpeg=jpeg,
                crc32=jpeg_crc32(jpeg)))
        if depth is not None:
            with p.part("depth_codec"):
                k = s.depth.decimation
                units = depth[::k, ::k] if k > 1 else depth
                self._depth = encode(DepthFrame(
                    header=header, camera=s.name, width=units.shape[1], height=units.shape[0],
                    codec=s.depth.codec, data=encode_depth(units, s.depth.codec)))

    def _messages(self) -> tuple[bytes, bytes | None]:
        """The CompressedFrame and DepthFrame (None without depth) as published."""
        if self._jpeg is None:
            self._produce()
        assert self._jpeg is not None
        return self._jpeg, self._depth

    def gray(self) -> np.ndarray:
        """The pixels fusion decodes from the JPEG. Raises FrameError."""
        cam = self.camera
        jpeg = self._messages()[0]
        with cam.profile.part("jpeg_decode"):
            return RecordedJpeg(jpeg, self.rx_mono_ns, cam.width, cam.height)()

    def depth_m(self) -> np.ndarray:
        """The depth fusion decodes from the DepthFrame. Raises FrameError."""
        cam = self.camera
        depth = self._messages()[1]
        assert depth is not None, "a frame without depth asked for its depth"
        with cam.profile.part("depth_codec"):
            return decode_depth_frame(depth, cam.width, cam.height)[1]


class LockstepCamera:
    """The camera's frames into `frames` (fusion's frame source). `with_depth`: each
    frame brings its depth (the verifier uses depth), else colour alone is rendered."""

    def __init__(self, scenes: SceneCamera, frames: FrameSource, settings: CameraSettings,
                 with_depth: bool, profile: Profile) -> None:
        self.scenes = scenes
        self.frames = frames
        self.settings = settings
        self.with_depth = with_depth
        self.profile = profile
        self.width, self.height = scenes.cal.width, scenes.cal.height
        self.period_ns = round(1e9 / settings.fps)
        self._seq = 0

    def capture(self, world: SimWorld, stamp_ns: int, rx_mono_ns: int) -> CapturedFrame:
        """A frame of `world` captured at `stamp_ns` (wall) reaching fusion at
        `rx_mono_ns`, in fusion's frame source from then on."""
        frame = CapturedFrame(self, world, self._seq, stamp_ns, rx_mono_ns)
        self._seq += 1
        self.profile.frames_captured += 1
        self.frames.add(self.settings.name, frame.seq, stamp_ns, rx_mono_ns, frame.gray,
                        frame.depth_m if self.with_depth else None)
        return frame
