"""The stack's messages as Foxglove sees them: one conversion for the MCAP recording
(`aeb record`, `aeb rerun`) and the live bridge (`aeb foxglove`), so that a drive looks
the same recorded and live.

Derived channels, all under ``/foxglove/<vehicle>/`` (`Topics`):

- camera/<camera>/image: foxglove.CompressedImage, from camera/<camera>/jpeg;
- camera/<camera>/calibration: foxglove.CameraCalibration, and tf: foxglove.FrameTransforms
  (the camera's frame in the radar's, by the calibration's extrinsics), from
  camera/<camera>/info: the 3D panel places the image, its annotations and the tracks in
  one scene;
- fusion/<instance>/annotations/<camera>: foxglove.ImageAnnotations, from
  fusion/<instance>/targets: each ROI on the frame it was checked in, coloured by state,
  labelled with range, TTC and the verifier's score;
- fusion/<instance>/scene: foxglove.SceneUpdate, the confirmed tracks from above with
  the path fusion judged by (the kinematic rule's arc to its range gate, or the paper's
  straight corridor);
- radar/<sensor>/scene: foxglove.SceneUpdate, every radar track, confirmed or not;
- fusion/<instance>/command, fusion/<instance>/threat, brake/plot: JSON views for plots
  (`CommandPlot`, `ThreatPlot`: the cycle's most severe track, `BrakePlot`);
- health: JSON `HealthView`, each service's liveliness and own status.

Foxglove messages are encoded by foxglove-sdk (protobuf, with its schema); the JSON
views are msgspec Structs with their JSON schema. `encode_derived` gives the bytes and
the channel type both sinks write.
"""

import math
from dataclasses import dataclass
from typing import Any

import cv2
import msgspec
import numpy as np
from foxglove import messages as fg

from aeb_radar_camera.common.config.fusion import CorridorSettings, DecisionSettings
from aeb_radar_camera.common.imaging import decode_bgr, encode_jpeg
from aeb_radar_camera.common.keys import (
    BRAKE_STATUS,
    CAMERA_INFO,
    CAMERA_JPEG,
    FUSION_BRAKE_CMD,
    FUSION_TARGETS,
    RADAR_STATUS,
    RADAR_TRACKS,
)
from aeb_radar_camera.common.messages import (
    BrakeCommand,
    BrakeState,
    BrakeStatus,
    CameraInfo,
    CompressedFrame,
    Decision,
    RadarStatus,
    RadarTracks,
    Verification,
    VerifiedTarget,
    VerifiedTargets,
)
from aeb_radar_camera.services.fusion.path import PredictedPath
from aeb_radar_camera.tools.recording.format import ChannelType

RADAR_FRAME = "radar"          # the 3-D views' frame: x forward, y left, z up (radar origin)
PATH_STEP_M = 1.0              # the drawn path's points along its arc
DECISION_LEVEL = {Decision.NONE: 0, Decision.WARNING: 1, Decision.BRAKE: 2}
BRAKE_LEVEL = {BrakeState.STANDBY: 0, BrakeState.ARMED: 1, BrakeState.BRAKING: 2,
               BrakeState.FAILSAFE: 3, BrakeState.FAULT: 4}

_RGBA = tuple[float, float, float, float]
_DECISION_COLOUR: dict[Decision, _RGBA] = {
    Decision.BRAKE: (0.95, 0.1, 0.1, 1.0), Decision.WARNING: (1.0, 0.6, 0.0, 1.0)}
_VERIFICATION_COLOUR: dict[Verification, _RGBA] = {
    Verification.VERIFIED: (0.1, 0.85, 0.25, 1.0),
    Verification.REJECTED: (0.55, 0.6, 1.0, 1.0),
    Verification.UNAVAILABLE: (1.0, 0.95, 0.2, 1.0),
    Verification.NOT_CHECKED: (0.7, 0.7, 0.7, 1.0),
    Verification.NOT_VISIBLE: (0.45, 0.45, 0.45, 1.0),
}


def state_colour(t: VerifiedTarget) -> _RGBA:
    """A target's colour: its decision when it is a WARNING or BRAKE, else its
    verification (verified green, rejected blue, unavailable yellow, not checked grey)."""
    return _DECISION_COLOUR.get(t.decision) or _VERIFICATION_COLOUR[t.verification]


def _colour(rgba: _RGBA, alpha: float | None = None) -> fg.Color:
    r, g, b, a = rgba
    return fg.Color(r=r, g=g, b=b, a=a if alpha is None else alpha)


def _stamp(ns: int) -> fg.Timestamp:
    return fg.Timestamp(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)


def _fmt(value: float | None, unit: str, digits: int = 1) -> str:
    return "-" if value is None else f"{value:.{digits}f} {unit}"


def target_label(t: VerifiedTarget, verifier: str) -> str:
    """`#7 12.3 m TTC 2.1 s combined 1.557 verified BRAKE`: the score named by the
    verifier that gave it (`density` is whatever score the instance's verifier gives;
    an edge density only for the edge-density verifiers)."""
    score = "-" if t.density is None else f"{t.density:.3g}"
    return (f"#{t.track_id} {t.range_m:.1f} m TTC {_fmt(t.ttc_s, 's')} {verifier} {score} "
            f"{t.verification.value} {t.decision.value}")


def frame_stamp_ns(targets: VerifiedTargets, t: VerifiedTarget) -> int | None:
    """The capture stamp of the frame `t` was checked in (the radar cycle's stamp minus
    the frame's age), None when it was checked in none."""
    if t.frame_seq is None or t.frame_age_ms is None:
        return None
    return targets.header.stamp_ns - round(t.frame_age_ms * 1e6)


# -- JSON views ------------------------------------------------------------------------


class CommandPlot(msgspec.Struct, frozen=True):
    """One fusion command, for plots: decision level 0 NONE, 1 WARNING, 2 BRAKE."""

    radar_seq: int
    decision: str
    decision_level: int
    brake_level_pct: float
    held: bool
    track_id: int
    range_m: float | None
    ttc_s: float | None
    verifier_status: str


class ThreatPlot(msgspec.Struct, frozen=True):
    """A fusion cycle's most severe confirmed track (ties: the smallest TTC_eff), for
    plots; `threshold` is the verifier's `tau` when it has one."""

    radar_seq: int
    confirmed: int
    track_id: int
    range_m: float | None
    ttc_s: float | None
    ttc_eff_s: float | None
    density: float | None
    threshold: float | None
    verification: str
    decision: str
    decision_level: int
    in_path: bool
    verifier_status: str


class BrakePlot(msgspec.Struct, frozen=True):
    """The brake's state for plots: 0 STANDBY, 1 ARMED, 2 BRAKING, 3 FAILSAFE, 4 FAULT."""

    state: str
    state_level: int
    commanded_level_pct: float
    actuator_position_pct: float | None
    cmd_to_serial_us: float | None
    radar_to_serial_us: float | None
    reason: str


class ServiceHealth(msgspec.Struct, frozen=True):
    service: str
    instance: str
    alive: bool                # its liveliness token is up
    status: str                # from its own status message: "ok" or why not
    detail: str


class HealthView(msgspec.Struct, frozen=True):
    services: tuple[ServiceHealth, ...]


JSON_VIEWS: tuple[type[msgspec.Struct], ...] = (CommandPlot, ThreatPlot, BrakePlot, HealthView)


def object_schema(msg_type: type[msgspec.Struct]) -> dict[str, Any]:
    """msgspec's JSON schema with the type itself at the root (`"type": "object"`), as
    Foxglove's WebSocket protocol wants it."""
    schema = msgspec.json.schema(msg_type)
    defs = schema.get("$defs", {})
    return {**defs[msg_type.__name__], "$defs": defs}


_JSON_TYPES: dict[type[Any], ChannelType] = {}


def json_channel(msg_type: type[msgspec.Struct]) -> ChannelType:
    kind = _JSON_TYPES.get(msg_type)
    if kind is None:
        kind = _JSON_TYPES[msg_type] = ChannelType(
            f"aeb.view.{msg_type.__name__}", "jsonschema",
            msgspec.json.encode(object_schema(msg_type)), "json")
    return kind


def encode_derived(msg: Any) -> tuple[ChannelType, bytes]:
    """A derived message's channel type and bytes: a Foxglove message in protobuf (its
    schema from foxglove-sdk), a JSON view as JSON. Raises TypeError for anything else."""
    if isinstance(msg, msgspec.Struct):
        return json_channel(type(msg)), msgspec.json.encode(msg)
    get_schema = getattr(type(msg), "get_schema", None)
    if get_schema is None:
        raise TypeError(f"not a derived message: {type(msg).__name__}")
    schema = get_schema()
    return ChannelType(schema.name, schema.encoding, bytes(schema.data), "protobuf"), \
        msg.encode()


# -- the conversions ----------------------------------------------------------------------


@dataclass(frozen=True)
class Topics:
    vehicle: str

    def image(self, camera: str) -> str:
        return f"/foxglove/{self.vehicle}/camera/{camera}/image"

    def annotations(self, instance: str, camera: str) -> str:
        return f"/foxglove/{self.vehicle}/fusion/{instance}/annotations/{camera}"

    def fusion_scene(self, instance: str) -> str:
        return f"/foxglove/{self.vehicle}/fusion/{instance}/scene"

    def radar_scene(self, sensor: str) -> str:
        return f"/foxglove/{self.vehicle}/radar/{sensor}/scene"

    def command(self, instance: str) -> str:
        return f"/foxglove/{self.vehicle}/fusion/{instance}/command"

    def threat(self, instance: str) -> str:
        return f"/foxglove/{self.vehicle}/fusion/{instance}/threat"

    def brake(self) -> str:
        return f"/foxglove/{self.vehicle}/brake/plot"

    def health(self) -> str:
        return f"/foxglove/{self.vehicle}/health"

    def calibration(self, camera: str) -> str:
        return f"/foxglove/{self.vehicle}/camera/{camera}/calibration"

    def transforms(self) -> str:
        return f"/foxglove/{self.vehicle}/tf"


Derived = tuple[str, Any]      # (topic, a Foxglove message or a JSON view)


class Converter:
    """Stack messages in, derived messages out (pure apart from its health memory).

    `decision`: the fusion settings whose corridor and range the scene draws (the shipped
    defaults when the fusion config is not at hand). `scale`: images and annotations
    resized by this factor (the bridge's `--scale`; 1 keeps the JPEG as it is)."""

    def __init__(self, vehicle: str, decision: DecisionSettings | None = None,
                 scale: float = 1.0, jpeg_quality: int = 70) -> None:
        if not 0 < scale <= 1:
            raise ValueError(f"scale must be in (0, 1], got {scale}")
        self.topics = Topics(vehicle)
        self.decision = decision or DecisionSettings()
        self.scale = scale
        self.jpeg_quality = jpeg_quality
        self._alive: dict[tuple[str, str], bool] = {}
        self._status: dict[tuple[str, str], tuple[str, str]] = {}

    def convert(self, spec_name: str, msg: Any) -> list[Derived]:
        """The derived messages of one stack message (none for keys without a view).
        Raises ImageDecodeError only when scaling an undecodable JPEG."""
        if spec_name == CAMERA_JPEG.name:
            return [(self.topics.image(msg.camera), self.image(msg))]
        if spec_name == FUSION_TARGETS.name:
            out: list[Derived] = [
                (self.topics.annotations(msg.instance, camera), ann)
                for camera, ann in self.annotations(msg).items()]
            out.append((self.topics.fusion_scene(msg.instance), self.fusion_scene(msg)))
            out.append((self.topics.threat(msg.instance), threat_plot(msg)))
            return out
        if spec_name == FUSION_BRAKE_CMD.name:
            return [(self.topics.command(msg.instance), command_plot(msg))]
        if spec_name == RADAR_TRACKS.name:
            return [(self.topics.radar_scene(msg.sensor), radar_scene(msg))]
        if spec_name == BRAKE_STATUS.name:
            return [(self.topics.brake(), brake_plot(msg)), *self._health_status(
                "brake", "main", msg)]
        if spec_name == CAMERA_INFO.name:
            return [(self.topics.calibration(msg.camera), self.calibration(msg)),
                    (self.topics.transforms(), camera_transforms(msg)),
                    *self._health_status(*_service_of(msg), msg)]
        if spec_name == RADAR_STATUS.name:
            return self._health_status(*_service_of(msg), msg)
        return []

    # -- camera -----------------------------------------------------------------------

    def image(self, frame: CompressedFrame) -> fg.CompressedImage:
        data = frame.jpeg
        if self.scale != 1.0:
            bgr = decode_bgr(frame.jpeg, frame.crc32)
            size = (max(1, round(frame.width * self.scale)),
                    max(1, round(frame.height * self.scale)))
            data = encode_jpeg(cv2.resize(bgr, size, interpolation=cv2.INTER_AREA),
                               self.jpeg_quality)
        return fg.CompressedImage(timestamp=_stamp(frame.header.stamp_ns),
                                  frame_id=frame.camera, data=data, format="jpeg")

    def calibration(self, info: CameraInfo) -> fg.CameraCalibration:
        """The camera's intrinsics in the image's frame (the camera's name), for the 3D
        panel to place the image and its annotations; scaled with the images."""
        s = self.scale
        fx, _, cx, _, fy, cy, _, _, _ = info.k
        k = [fx * s, 0.0, cx * s, 0.0, fy * s, cy * s, 0.0, 0.0, 1.0]
        dist = list(info.dist)
        model = "rational_polynomial" if len(dist) >= 8 else "plumb_bob"
        dist = (dist + [0.0] * 8)[:8 if model == "rational_polynomial" else 5]
        return fg.CameraCalibration(
            timestamp=_stamp(info.header.stamp_ns), frame_id=info.camera,
            width=max(1, round(info.width * s)), height=max(1, round(info.height * s)),
            distortion_model=model, D=dist, K=k, R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            P=[k[0], 0.0, k[2], 0.0, 0.0, k[4], k[5], 0.0, 0.0, 0.0, 1.0, 0.0])

    def annotations(self, targets: VerifiedTargets) -> dict[str, fg.ImageAnnotations]:
        """Per camera, the ROIs of the cycle on the frame they were checked in (stamped
        with that frame's capture time, as Foxglove pairs image and annotations)."""
        by_camera: dict[str, tuple[int, list[fg.PointsAnnotation], list[fg.TextAnnotation]]] = {}
        # A message that names no camera (older or hand-made) gets one topic all the same.
        default_camera = targets.camera.split(",")[0] if targets.camera else "camera"
        s = self.scale
        for t in targets.targets:
            stamp = frame_stamp_ns(targets, t)
            if stamp is None or len(t.roi_xywh) != 4:
                continue
            camera = t.camera or default_camera
            entry = by_camera.setdefault(camera, (stamp, [], []))
            x, y, w, h = (v * s for v in t.roi_xywh)
            colour = state_colour(t)
            ts = _stamp(entry[0])
            entry[1].append(fg.PointsAnnotation(
                timestamp=ts, type=fg.PointsAnnotationType.LineLoop,
                points=[fg.Point2(x=x, y=y), fg.Point2(x=x + w, y=y),
                        fg.Point2(x=x + w, y=y + h), fg.Point2(x=x, y=y + h)],
                outline_color=_colour(colour), thickness=max(1.0, 2.0 * s)))
            entry[2].append(fg.TextAnnotation(
                timestamp=ts, position=fg.Point2(x=x, y=max(0.0, y - 4 * s)),
                text=target_label(t, targets.verifier), font_size=max(8.0, 13.0 * s),
                text_color=_colour(colour), background_color=fg.Color(r=0, g=0, b=0, a=0.6)))
        return {camera: fg.ImageAnnotations(points=points, texts=texts)
                for camera, (_, points, texts) in by_camera.items()}

    # -- bird's-eye ---------------------------------------------------------------------

    def fusion_scene(self, targets: VerifiedTargets) -> fg.SceneUpdate:
        """The confirmed tracks (at the position they were projected from), coloured by
        state and labelled, the corridor, and the decision's range."""
        ts = _stamp(targets.header.stamp_ns)
        entities = [self._path(ts, targets) if targets.path_curvature_per_m is not None
                    else self._corridor(ts)]
        for t in targets.targets:
            if not (math.isfinite(t.x_m) and math.isfinite(t.y_m)):
                continue
            colour = state_colour(t)
            entities.append(fg.SceneEntity(
                timestamp=ts, frame_id=RADAR_FRAME, id=f"track-{t.track_id}",
                cubes=[fg.CubePrimitive(pose=_pose(t.x_m, t.y_m, 0.8),
                                        size=fg.Vector3(x=0.8, y=0.8, z=1.6),
                                        color=_colour(colour, 0.7))],
                texts=[fg.TextPrimitive(pose=_pose(t.x_m, t.y_m, 2.0), billboard=True,
                                        font_size=14.0, scale_invariant=True,
                                        color=_colour(colour),
                                        text=target_label(t, targets.verifier))],
                metadata=[fg.KeyValuePair(key="in_path", value=str(t.in_path)),
                          fg.KeyValuePair(key="reason", value=t.reason)]))
        return fg.SceneUpdate(
            deletions=[fg.SceneEntityDeletion(timestamp=ts,
                                              type=fg.SceneEntityDeletionType.All)],
            entities=entities)

    def _corridor(self, ts: fg.Timestamp) -> fg.SceneEntity:
        c: CorridorSettings = self.decision.corridor
        far = self.decision.max_range_m
        near = self.decision.min_range_m
        lines = []
        for offset, colour in ((c.half_width_m, (1.0, 1.0, 1.0, 0.9)),
                               (c.half_width_m + c.margin_m, (1.0, 1.0, 1.0, 0.35))):
            for side in (-1, 1):
                y = c.center_y_m + side * offset
                lines.append(fg.LinePrimitive(
                    type=fg.LinePrimitiveLineType.LineStrip, thickness=0.05,
                    points=[fg.Point3(x=0.0, y=y, z=0.0), fg.Point3(x=far, y=y, z=0.0)],
                    color=_colour(colour)))
        for x in (near, far):
            y0 = c.center_y_m - c.half_width_m - c.margin_m
            y1 = c.center_y_m + c.half_width_m + c.margin_m
            lines.append(fg.LinePrimitive(
                type=fg.LinePrimitiveLineType.LineStrip, thickness=0.03,
                points=[fg.Point3(x=x, y=y0, z=0.0), fg.Point3(x=x, y=y1, z=0.0)],
                color=_colour((0.6, 0.8, 1.0, 0.6))))
        return fg.SceneEntity(timestamp=ts, frame_id=RADAR_FRAME, id="corridor",
                              lines=lines,
                              metadata=[fg.KeyValuePair(key="enabled", value=str(c.enabled))])

    def _path(self, ts: fg.Timestamp, targets: VerifiedTargets) -> fg.SceneEntity:
        """The kinematic rule's path as fusion judged by it this cycle: its arc (the
        recorded curvature), half-width and margin either side, from the rule's near bound
        to its range gate."""
        p = self.decision.path
        path = PredictedPath(targets.path_curvature_per_m or 0.0, p.half_width_m + p.margin_m,
                             p.length_m, self.decision.corridor.center_y_m)
        near = self.decision.kinematic.range_min_m
        far = targets.range_gate_m if targets.range_gate_m is not None else p.length_m
        steps = max(2, math.ceil((far - near) / PATH_STEP_M) + 1)
        along = [near + (far - near) * i / (steps - 1) for i in range(steps)]

        def line(points: list[tuple[float, float]], width: float,
                 colour: _RGBA) -> fg.LinePrimitive:
            return fg.LinePrimitive(
                type=fg.LinePrimitiveLineType.LineStrip, thickness=width,
                points=[fg.Point3(x=x, y=y, z=0.0) for x, y in points], color=_colour(colour))

        edge = path.half_width_m
        lines = [line([path.at(s_m, side * offset) for s_m in along], 0.05, colour)
                 for offset, colour in ((p.half_width_m, (1.0, 1.0, 1.0, 0.9)),
                                        (edge, (1.0, 1.0, 1.0, 0.35)))
                 for side in (-1, 1)]
        lines += [line([path.at(s_m, -edge), path.at(s_m, edge)], 0.03, (0.6, 0.8, 1.0, 0.6))
                  for s_m in (near, far)]
        return fg.SceneEntity(timestamp=ts, frame_id=RADAR_FRAME, id="corridor", lines=lines,
                              metadata=[fg.KeyValuePair(key="path", value=targets.path)])

    # -- health -------------------------------------------------------------------------

    def health(self, service: str, instance: str, alive: bool) -> Derived:
        """A liveliness token appeared or vanished: the health view."""
        self._alive[(service, instance)] = alive
        return self.topics.health(), self._health_view()

    def _health_status(self, service: str, instance: str, msg: Any) -> list[Derived]:
        status = _status_of(msg)
        if self._status.get((service, instance)) == status:
            return []
        self._status[(service, instance)] = status
        return [(self.topics.health(), self._health_view())]

    def _health_view(self) -> HealthView:
        names = sorted(set(self._alive) | set(self._status))
        return HealthView(tuple(
            ServiceHealth(s, i, self._alive.get((s, i), False),
                          *self._status.get((s, i), ("unknown", "no status received")))
            for s, i in names))


def camera_transforms(info: CameraInfo) -> fg.FrameTransforms:
    """The camera's frame (its optical frame: x right, y down, z into the image) placed
    in the radar's by the calibration's extrinsics. CameraInfo maps radar to camera,
    X_cam = R X_radar + t; Foxglove wants the child's pose in the parent, so the
    rotation is R^T and the translation -R^T t (the camera's centre in radar
    coordinates)."""
    r = np.array(info.r, float).reshape(3, 3)
    t = np.array(info.t_m, float).reshape(3)
    rotation = r.T
    centre = -rotation @ t
    rvec, _ = cv2.Rodrigues(rotation)
    angle = float(np.linalg.norm(rvec))
    axis = (rvec.reshape(3) / angle) if angle > 0 else np.zeros(3)
    qx, qy, qz = (axis * math.sin(angle / 2)).tolist()
    return fg.FrameTransforms(transforms=[fg.FrameTransform(
        timestamp=_stamp(info.header.stamp_ns), parent_frame_id=RADAR_FRAME,
        child_frame_id=info.camera,
        translation=fg.Vector3(x=float(centre[0]), y=float(centre[1]), z=float(centre[2])),
        rotation=fg.Quaternion(x=qx, y=qy, z=qz, w=math.cos(angle / 2)))])


def _pose(x: float, y: float, z: float) -> fg.Pose:
    return fg.Pose(position=fg.Vector3(x=x, y=y, z=z),
                   orientation=fg.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))


def radar_scene(tracks: RadarTracks) -> fg.SceneUpdate:
    """Every radar track from above: confirmed ones as boxes, tentative ones as small
    spheres, each with its velocity as an arrow."""
    ts = _stamp(tracks.header.stamp_ns)
    entities = []
    for t in tracks.tracks:
        if not all(map(math.isfinite, (t.x_m, t.y_m, t.vx_mps, t.vy_mps))):
            continue
        colour = (0.2, 0.7, 1.0, 0.8) if t.confirmed else (0.6, 0.6, 0.6, 0.5)
        speed = math.hypot(t.vx_mps, t.vy_mps)
        yaw = math.atan2(t.vy_mps, t.vx_mps)
        arrow = fg.ArrowPrimitive(
            pose=fg.Pose(position=fg.Vector3(x=t.x_m, y=t.y_m, z=0.1),
                         orientation=fg.Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                   w=math.cos(yaw / 2))),
            shaft_length=max(0.05, speed * 0.5), shaft_diameter=0.08, head_length=0.2,
            head_diameter=0.25, color=_colour(colour))
        shape: dict[str, Any] = (
            {"cubes": [fg.CubePrimitive(pose=_pose(t.x_m, t.y_m, 0.5),
                                        size=fg.Vector3(x=0.6, y=0.6, z=1.0),
                                        color=_colour(colour))]} if t.confirmed else
            {"spheres": [fg.SpherePrimitive(pose=_pose(t.x_m, t.y_m, 0.3),
                                            size=fg.Vector3(x=0.4, y=0.4, z=0.4),
                                            color=_colour(colour))]})
        entities.append(fg.SceneEntity(
            timestamp=ts, frame_id=RADAR_FRAME, id=f"radar-{t.track_id}", arrows=[arrow],
            texts=[fg.TextPrimitive(pose=_pose(t.x_m, t.y_m, 1.3), billboard=True,
                                    font_size=12.0, scale_invariant=True,
                                    color=_colour(colour),
                                    text=f"#{t.track_id} {t.range_m:.1f} m "
                                         f"{t.range_rate_mps:+.1f} m/s")],
            **shape))
    return fg.SceneUpdate(
        deletions=[fg.SceneEntityDeletion(timestamp=ts, type=fg.SceneEntityDeletionType.All)],
        entities=entities)


def command_plot(cmd: BrakeCommand) -> CommandPlot:
    return CommandPlot(cmd.radar_seq, cmd.decision.value, DECISION_LEVEL[cmd.decision],
                       cmd.brake_level_pct, cmd.held, cmd.track_id, cmd.range_m, cmd.ttc_s,
                       cmd.verifier_status.value)


def threat_plot(targets: VerifiedTargets) -> ThreatPlot:
    confirmed = [t for t in targets.targets if math.isfinite(t.range_m)]

    def rank(t: VerifiedTarget) -> tuple[int, float]:
        ttc = t.ttc_eff_s if t.ttc_eff_s is not None else math.inf
        return DECISION_LEVEL[t.decision], -ttc

    tau = targets.verifier_params.get("tau")
    threshold = float(tau) if isinstance(tau, int | float) and not isinstance(tau, bool) \
        else None
    status = targets.verifier_status.value
    if not confirmed:
        return ThreatPlot(targets.radar_seq, 0, -1, None, None, None, None, threshold,
                          "", Decision.NONE.value, 0, False, status)
    t = max(confirmed, key=rank)
    return ThreatPlot(targets.radar_seq, len(confirmed), t.track_id, t.range_m, t.ttc_s,
                      t.ttc_eff_s, t.density, threshold, t.verification.value,
                      t.decision.value, DECISION_LEVEL[t.decision], t.in_path, status)


def brake_plot(status: BrakeStatus) -> BrakePlot:
    return BrakePlot(status.state.value, BRAKE_LEVEL[status.state],
                     status.commanded_level_pct, status.actuator_position_pct,
                     status.cmd_to_serial_us, status.radar_to_serial_us, status.reason)


def _service_of(msg: Any) -> tuple[str, str]:
    if isinstance(msg, RadarStatus):
        return "radar", msg.sensor
    return "camera", msg.camera


def _status_of(msg: Any) -> tuple[str, str]:
    """("ok" or why not, a short detail) from a service's own status message."""
    if isinstance(msg, RadarStatus):
        return ("ok" if msg.ready else msg.not_ready_reason,
                f"bus {msg.bus_state.value}, cycle {msg.cycle_period_ms:.1f} ms")
    if isinstance(msg, CameraInfo):
        return ("ok" if msg.healthy else msg.status,
                f"{msg.source} {msg.width}x{msg.height} at {msg.fps:g} fps")
    assert isinstance(msg, BrakeStatus)
    bad = msg.state in (BrakeState.FAILSAFE, BrakeState.FAULT) or not msg.actuator_connected
    return (msg.reason or msg.state.value if bad else "ok",
            f"{msg.state.value}, following {msg.instance}")
