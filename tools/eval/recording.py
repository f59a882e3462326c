"""ROIs from a recording, exactly as fusion builds them: for every radar cycle, each
camera's frame is chosen among the frames fusion would hold at that moment (its ring of
the last RING_SIZE decoded frames received before the cycle, tools/recording/
frame_source.py) by fusion's own `select_frame`, the tracks are predicted to that frame's
capture time and projected by fusion's `camera_views` with the ColumnProjector of the
fusion configuration (padding, clipping), and every confirmed track in the decision's
range (3-25 m) becomes a ROI.

Frames are decoded only when chosen: a frame that turns out undecodable is dropped from
the ring (fusion never holds one) and the choice is made again; it is counted.

Recordings of the simulator carry its ground truth (`sim/world`); their tracks are then
labelled by it (tools/eval/sim_truth.py) and get background negatives like a data set's.

Depth: where the recording holds a camera's `camera/<name>/depth`, the depth with the
chosen frame's capture stamp is decoded as fusion decodes it and given to every verifier
(with the calibration and the track's position); a frame without its depth leaves the
depth verifiers not applicable for its ROIs (`frame_without_depth`).
"""

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from common.calibration import Calibration
from common.config.fusion import FusionSettings
from common.keys import CAMERA_DEPTH, CAMERA_INFO, CAMERA_JPEG, RADAR_TRACKS
from common.messages import (
    CameraInfo,
    CompressedFrame,
    DecodeError,
    DepthFrame,
    RadarTracks,
    decode,
)
from common.messages.schema import schema_name
from services.fusion.cameras import Camera, camera_views
from services.fusion.core import finite_track
from services.fusion.frames import FrameError
from services.fusion.roi import ColumnGeometry, ColumnProjector, Roi
from services.fusion.verifiers import Observation
from tools.eval import sim_truth
from tools.eval.adapters.paper_rois import free_rois
from tools.eval.records import KIND_TRACK, FrameRef, RoiRecord
from tools.eval.scoring import Scorer, lighting
from tools.messages import SimWorld
from tools.recording.frame_source import FrameSource
from tools.recording.reader import ChannelSummary, Recording, RecordingError

_FRAME = schema_name(CompressedFrame)
_INFO = schema_name(CameraInfo)
_DEPTH = schema_name(DepthFrame)
_TRACKS = schema_name(RadarTracks)
_WORLD = schema_name(SimWorld)

@dataclass(frozen=True)
class RecordingSettings:
    fusion: FusionSettings = field(default_factory=FusionSettings)
    # camera -> calibration TOML; the others come from the recording's CameraInfo, else
    # from the fusion settings' files.
    calibrations: dict[str, str] = field(default_factory=dict)
    prefer_config_calibration: bool = False   # fusion's files before CameraInfo
    background_per_object: int = 2            # with ground truth only
    timing: bool = True
    seed: int = 0


def _vehicle(topic: str) -> str:
    parts = topic.split("/")
    return parts[1] if len(parts) > 2 and parts[0] == "aeb" else ""


def _calibration_from_info(info: CameraInfo) -> Calibration:
    return Calibration.from_matrices(info.width, info.height,
                                     np.array(info.k).reshape(3, 3), np.array(info.dist),
                                     np.array(info.r).reshape(3, 3), np.array(info.t_m),
                                     name=f"camera_info:{info.camera}")


def _bump(counters: dict[str, int], key: str, n: int = 1) -> None:
    counters[key] = counters.get(key, 0) + n


class _Cameras:
    """Per camera: its topic, calibration, projector and the frames received so far."""

    def __init__(self, recording: Recording, chans: list[ChannelSummary], s: RecordingSettings,
                 counters: dict[str, int]) -> None:
        wanted = [c.name for c in s.fusion.camera_inputs]
        config_files = {c.name: c.calibration for c in s.fusion.camera_inputs}
        self.topics: dict[str, str] = {}
        info_topics: dict[str, str] = {}
        depth_topics: dict[str, str] = {}
        for ch in chans:
            vehicle = _vehicle(ch.topic)
            got = CAMERA_JPEG.match(ch.topic, vehicle)
            if got is not None and ch.schema_name == _FRAME:
                self.topics[got["camera"]] = ch.topic
            got = CAMERA_INFO.match(ch.topic, vehicle)
            if got is not None and ch.schema_name == _INFO:
                info_topics[got["camera"]] = ch.topic
            got = CAMERA_DEPTH.match(ch.topic, vehicle)
            if got is not None and ch.schema_name == _DEPTH:
                depth_topics[got["camera"]] = ch.topic
        self.names = [n for n in wanted if n in self.topics]
        missing = [n for n in wanted if n not in self.topics]
        if missing:
            _bump(counters, "camera_not_recorded", len(missing))
        self.calibration_source: dict[str, str] = {}
        cals: dict[str, Calibration] = {}
        for name in self.names:
            cals[name] = self._calibration(recording, name, s, config_files.get(name, ""),
                                           info_topics.get(name))
        geometry = ColumnGeometry(s.fusion.roi.column_height_m,
                                  s.fusion.roi.column_half_width_m, s.fusion.roi.padding_px)
        self.cals = cals
        self.cameras = [Camera(n, ColumnProjector(cals[n], geometry)) for n in self.names]
        self.by_topic = {self.topics[n]: n for n in self.names}
        # Only cameras with a depth topic.
        self.by_depth_topic = {depth_topics[n]: n for n in self.names if n in depth_topics}
        self.source = FrameSource({n: (c.width, c.height) for n, c in cals.items()}, counters)

    def depth_at(self, name: str, stamp_ns: int, counters: dict[str, int]) -> np.ndarray | None:
        """The camera's depth for the frame captured at `stamp_ns` (metres at the
        frame's size), or None (no depth recorded for it, or unusable: counted)."""
        if name not in self.by_depth_topic.values():
            return None
        if not self.source.depth.has(name, stamp_ns):
            _bump(counters, "frame_without_depth")
            return None
        return self.source.depth.at(name, stamp_ns)

    def _calibration(self, recording: Recording, name: str, s: RecordingSettings, config_file: str,
                     info_topic: str | None) -> Calibration:
        if name in s.calibrations:
            self.calibration_source[name] = s.calibrations[name]
            return Calibration.load(s.calibrations[name])
        if s.prefer_config_calibration or info_topic is None:
            self.calibration_source[name] = config_file
            return Calibration.load(config_file)
        for m in recording.records([info_topic]):
            try:
                info = decode(m.data, CameraInfo)
            except DecodeError:
                continue
            self.calibration_source[name] = f"{info_topic} (CameraInfo)"
            return _calibration_from_info(info)
        self.calibration_source[name] = config_file
        return Calibration.load(config_file)



def recording_records(path: Path, s: RecordingSettings, scorer: Scorer,
                      counters: dict[str, int]) -> list[RoiRecord]:
    """Every confirmed track in range, in every camera that sees it, scored by every
    verifier. Raises RecordingError (unreadable file, no radar or camera channel),
    ConfigError (a calibration file)."""
    recording = Recording.open(path)
    chans = [c for c in recording.channels().values() if c.message_encoding == "msgpack"]
    tracks_topics = [c.topic for c in chans if c.schema_name == _TRACKS
                     and RADAR_TRACKS.match(c.topic, _vehicle(c.topic)) is not None]
    if not tracks_topics:
        raise RecordingError(f"{path}: no RadarTracks channel")
    cams = _Cameras(recording, chans, s, counters)
    if not cams.names:
        raise RecordingError(f"{path}: none of the cameras fusion uses "
                             f"({', '.join(c.name for c in s.fusion.camera_inputs)}) is "
                             "recorded")
    world_topics = [c.topic for c in chans if c.schema_name == _WORLD]
    truth = sim_truth.Truth() if world_topics else None
    decision = s.fusion.decision
    max_skew_ns = round(s.fusion.frames.max_skew_s * 1e9)
    rng = np.random.default_rng(s.seed)
    session = path.stem
    out: list[RoiRecord] = []
    timed_frames: set[tuple[str, int]] = set()
    topics = tracks_topics + list(cams.by_topic) + list(cams.by_depth_topic) + world_topics
    for m in recording.records(topics):
        if m.topic in cams.by_depth_topic:
            cams.source.add_depth(cams.by_depth_topic[m.topic], m.data, m.log_time_ns)
            continue
        if m.topic in cams.by_topic:
            try:
                cams.source.add_recorded(cams.by_topic[m.topic], m.data, m.log_time_ns)
            except DecodeError:
                _bump(counters, "frame_message")
            continue
        if truth is not None and m.topic in world_topics:
            truth.add(m.data, counters)
            continue
        try:
            cycle = decode(m.data, RadarTracks)
        except DecodeError:
            _bump(counters, "tracks_message")
            continue
        _bump(counters, "radar_cycles")
        tracks = [t for t in cycle.tracks if t.confirmed and finite_track(t)
                  and decision.min_range_m <= t.range_m <= decision.max_range_m]
        if not tracks:
            continue
        stamp = cycle.header.stamp_ns
        for cam in cams.cameras:
            name = cam.name
            cal = cams.cals[name]
            while True:
                feed = cams.source.feed(name, m.log_time_ns)
                view = camera_views([cam], [feed], tracks, stamp, max_skew_ns,
                                    s.fusion.frames.align)[0]
                if view.frame is None:
                    gray, stub = None, None
                    break
                stub = view.frame
                try:
                    gray = stub.gray
                    break
                except FrameError as exc:
                    _bump(counters, f"frame_{exc.reason}")
            if view.frame is None or gray is None or stub is None:
                _bump(counters, "cycle_without_frame")
                continue
            depth = cams.depth_at(name, stub.stamp_ns, counters)
            if depth is not None:
                scorer.prepare(cal)
            light, median = lighting(gray)
            world = truth.world_at(stamp) if truth is not None else None
            positives: list[tuple[RoiRecord, tuple[float, float]]] = []
            for i, track in enumerate(tracks):
                roi, column = view.rois[i], view.columns[i]
                if roi is None or column is None:
                    _bump(counters, "track_not_visible")
                    continue
                x, y = view.xy[i]
                obs = Observation(gray, roi, column, math.hypot(x, y), depth, cal, (x, y))
                scores = scorer.score(obs)
                frame_us = None
                if s.timing and (name, stub.seq) not in timed_frames:
                    timed_frames.add((name, stub.seq))
                    frame_us = scorer.full_frame_us(gray)
                label, obj_class = (None, "")
                if world is not None:
                    label, obj_class = sim_truth.label_track(world, stamp, track.x_m,
                                                             track.y_m)
                rec = RoiRecord(
                    id=f"{session}:{stamp}:{name}:{track.track_id}", source="recording",
                    session=session, frame=f"{name}:{stub.seq}", t_ns=stamp, camera=name,
                    image_w=cal.width, image_h=cal.height, roi=roi,
                    column=column, range_m=track.range_m, kind=KIND_TRACK,
                    frame_ref=FrameRef("mcap", str(path), cams.topics[name],
                                       stub.rx_mono_ns, stub.seq),
                    ttc_s=(track.range_m / -track.range_rate_mps
                           if track.range_rate_mps < 0 else None),
                    track_id=track.track_id, obj_class=obj_class, truth=label,
                    density=scorer.density(obs, scores), lighting=light,
                    frame_median=median, has_depth=depth is not None, scores=scores,
                    frame_canny_us=frame_us)
                out.append(rec)
                if label == "YES":
                    positives.append((rec, (x, y)))
            if world is not None and positives and s.background_per_object > 0:
                out += _background(world, view.frame.stamp_ns, cal, gray, depth, positives,
                                   s, scorer, rng, counters, (light, median))
    counters["rois"] = counters.get("rois", 0) + len(out)
    return out


def _background(world: SimWorld, frame_stamp: int, cal: Calibration,
                gray: np.ndarray, depth: np.ndarray | None,
                positives: list[tuple[RoiRecord, tuple[float, float]]],
                s: RecordingSettings, scorer: Scorer, rng: np.random.Generator,
                counters: dict[str, int], light: tuple[str, float]) -> list[RoiRecord]:
    """Background negatives of a simulated frame: the positives' sizes and rows, where
    the ground truth has no object; each keeps its positive's column (moved with it) and
    range, as a radar target there would."""
    occupied = sim_truth.object_boxes(world, frame_stamp, cal)
    out = []
    for pos, xy in positives:
        got = free_rois(Roi(*pos.roi), occupied, cal.width, s.background_per_object, rng)
        if len(got) < s.background_per_object:
            _bump(counters, "background_no_room")
        # The positive's column, moved with its ROI (what a verifier of the column sees).
        px, py, pw, ph = pos.column
        dx, dy = px - pos.roi[0], py - pos.roi[1]
        for k, roi in enumerate(got):
            column = Roi(roi.x + dx, roi.y + dy, pw, ph)
            obs = Observation(gray, roi, column, pos.range_m, depth, cal, xy)
            scores = scorer.score(obs)
            out.append(RoiRecord(
                id=f"{pos.id}:bg{k}", source=pos.source, session=pos.session,
                frame=pos.frame, t_ns=pos.t_ns, camera=pos.camera, image_w=pos.image_w,
                image_h=pos.image_h, roi=roi, column=column, range_m=pos.range_m,
                kind="background", frame_ref=pos.frame_ref,
                truth="NO", density=scorer.density(obs, scores), lighting=light[0],
                frame_median=light[1], has_depth=depth is not None, scores=scores))
    return out
