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
from typing import Any

import numpy as np

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.config.fusion import FusionSettings
from aeb_radar_camera.common.keys import (
    CAMERA_DEPTH,
    CAMERA_INFO,
    CAMERA_JPEG,
    RADAR_TRACKS,
    KeySpec,
)
from aeb_radar_camera.common.messages import (
    CameraInfo,
    CompressedFrame,
    DecodeError,
    DepthFrame,
    RadarTrack,
    RadarTracks,
    decode,
)
from aeb_radar_camera.common.messages.schema import schema_name
from aeb_radar_camera.services.fusion.cameras import Camera, CameraView, camera_views
from aeb_radar_camera.services.fusion.core import finite_track
from aeb_radar_camera.services.fusion.frames import DecodedFrame, FrameError
from aeb_radar_camera.services.fusion.roi import ColumnGeometry, ColumnProjector, Roi
from aeb_radar_camera.services.fusion.verifiers import Observation
from aeb_radar_camera.tools.eval import sim_truth
from aeb_radar_camera.tools.eval.adapters.paper_rois import free_rois
from aeb_radar_camera.tools.eval.frames import content_digest
from aeb_radar_camera.tools.eval.records import KIND_TRACK, FrameRef, RoiRecord
from aeb_radar_camera.tools.eval.scoring import Scorer, lighting
from aeb_radar_camera.tools.messages import SimWorld
from aeb_radar_camera.tools.recording.frame_source import FrameSource
from aeb_radar_camera.tools.recording.reader import (
    ChannelSummary,
    Record,
    Recording,
    RecordingError,
)

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


@dataclass(frozen=True)
class _Channels:
    """The recording's topics ROIs are made from: radar tracks, each camera's frames,
    CameraInfo and depth, the simulator's ground truth."""

    tracks: list[str]
    frames: dict[str, str]
    infos: dict[str, str]
    depth: dict[str, str]
    world: list[str]

    @classmethod
    def of(cls, recording: Recording) -> "_Channels":
        chans = [c for c in recording.channels().values() if c.message_encoding == "msgpack"]
        return cls([c.topic for c in chans if c.schema_name == _TRACKS
                    and RADAR_TRACKS.match(c.topic, _vehicle(c.topic)) is not None],
                   _by_camera(chans, CAMERA_JPEG, _FRAME), _by_camera(chans, CAMERA_INFO, _INFO),
                   _by_camera(chans, CAMERA_DEPTH, _DEPTH),
                   [c.topic for c in chans if c.schema_name == _WORLD])


def _by_camera(chans: list[ChannelSummary], key: KeySpec[Any], schema: str) -> dict[str, str]:
    """camera -> topic, for the channels of `key` carrying `schema`."""
    out = {}
    for ch in chans:
        got = key.match(ch.topic, _vehicle(ch.topic))
        if got is not None and ch.schema_name == schema:
            out[got["camera"]] = ch.topic
    return out


class _Cameras:
    """The cameras fusion uses that the recording holds: calibration and projector."""

    def __init__(self, recording: Recording, channels: _Channels, s: RecordingSettings,
                 counters: dict[str, int]) -> None:
        wanted = [c.name for c in s.fusion.camera_inputs]
        config_files = {c.name: c.calibration for c in s.fusion.camera_inputs}
        self.names = [n for n in wanted if n in channels.frames]
        missing = [n for n in wanted if n not in channels.frames]
        if missing:
            _bump(counters, "camera_not_recorded", len(missing))
        self.calibration_source: dict[str, str] = {}
        self.cals = {name: self._calibration(recording, name, s, config_files.get(name, ""),
                                             channels.infos.get(name))
                     for name in self.names}
        geometry = ColumnGeometry(s.fusion.roi.column_height_m,
                                  s.fusion.roi.column_half_width_m, s.fusion.roi.padding_px)
        self.cameras = [Camera(n, ColumnProjector(self.cals[n], geometry)) for n in self.names]

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
    run = _RecordingRois(path, s, scorer, counters)
    out: list[RoiRecord] = []
    for m in run.recording.records(run.topics):
        out += run.take(m)
    counters["rois"] = counters.get("rois", 0) + len(out)
    return out


def _tracks_in_range(cycle: RadarTracks, s: FusionSettings) -> list[RadarTrack]:
    """The tracks fusion decides on (confirmed, finite) within the decision's range."""
    near, far = s.decision.range_bounds_m
    return [t for t in cycle.tracks if t.confirmed and finite_track(t)
            and near <= t.range_m <= far]


@dataclass(frozen=True)
class _Seen:
    """One camera in one radar cycle: its view, the frame chosen, its pixels and depth,
    the lighting, the calibration and the ground truth (simulator recordings)."""

    view: CameraView
    frame: DecodedFrame
    gray: np.ndarray
    depth: np.ndarray | None
    light: tuple[str, float]
    cal: Calibration
    world: SimWorld | None


class _RecordingRois:
    """One pass over a recording: its frames fed to fusion's ring as they come, the
    ROIs of each radar cycle made from it."""

    def __init__(self, path: Path, s: RecordingSettings, scorer: Scorer,
                 counters: dict[str, int]) -> None:
        self.recording = Recording.open(path)
        channels = _Channels.of(self.recording)
        if not channels.tracks:
            raise RecordingError(f"{path}: no RadarTracks channel")
        self.cams = _Cameras(self.recording, channels, s, counters)
        if not self.cams.names:
            raise RecordingError(f"{path}: none of the cameras fusion uses "
                                 f"({', '.join(c.name for c in s.fusion.camera_inputs)}) is "
                                 "recorded")
        self.path, self.s, self.scorer, self.counters = path, s, scorer, counters
        names = self.cams.names
        self.frame_topics = {channels.frames[n]: n for n in names}
        self.camera_topics = {n: channels.frames[n] for n in names}
        # Only cameras with a depth topic: a frame of the others has no depth to miss.
        self.depth_topics = {channels.depth[n]: n for n in names if n in channels.depth}
        self.world_topics = set(channels.world)
        self.topics = [*channels.tracks, *self.frame_topics, *self.depth_topics,
                       *channels.world]
        self.frames = FrameSource({n: (c.width, c.height) for n, c in self.cams.cals.items()},
                                  counters)
        self.truth = sim_truth.Truth() if channels.world else None
        self.max_skew_ns = round(s.fusion.frames.max_skew_s * 1e9)
        self.rng = np.random.default_rng(s.seed)
        self.timed_frames: set[tuple[str, int]] = set()
        self.digests: dict[tuple[str, int], str] = {}

    def take(self, m: Record) -> list[RoiRecord]:
        """The recording's next record; a radar cycle gives its ROIs."""
        if m.topic in self.depth_topics:
            self.frames.add_depth(self.depth_topics[m.topic], m.data, m.log_time_ns)
        elif m.topic in self.frame_topics:
            try:
                self.frames.add_recorded(self.frame_topics[m.topic], m.data, m.log_time_ns)
            except DecodeError:
                _bump(self.counters, "frame_message")
        elif m.topic in self.world_topics:
            if self.truth is not None:
                self.truth.add(m.data, self.counters)
        else:
            return self._cycle(m)
        return []

    def _cycle(self, m: Record) -> list[RoiRecord]:
        try:
            cycle = decode(m.data, RadarTracks)
        except DecodeError:
            _bump(self.counters, "tracks_message")
            return []
        _bump(self.counters, "radar_cycles")
        tracks = _tracks_in_range(cycle, self.s.fusion)
        if not tracks:
            return []
        stamp = cycle.header.stamp_ns
        out: list[RoiRecord] = []
        for cam in self.cams.cameras:
            seen = self._seen(cam, tracks, stamp, m.log_time_ns)
            if seen is None:
                _bump(self.counters, "cycle_without_frame")
            else:
                out += self._camera_records(seen, tracks, stamp)
        return out

    def _seen(self, cam: Camera, tracks: list[RadarTrack], stamp: int,
              at_ns: int) -> _Seen | None:
        """The camera's frame for the cycle as fusion chooses it, decoded (an
        undecodable one is counted and the choice made again), or None."""
        while True:
            feed = self.frames.feed(cam.name, at_ns)
            view = camera_views([cam], [feed], tracks, stamp, self.max_skew_ns,
                                self.s.fusion.frames.align)[0]
            if view.frame is None:
                return None
            try:
                gray = view.frame.gray
                break
            except FrameError as exc:
                _bump(self.counters, f"frame_{exc.reason}")
        cal = self.cams.cals[cam.name]
        depth = self._depth(view.frame)
        if depth is not None:
            self.scorer.prepare(cal)
        world = self.truth.world_at(stamp) if self.truth is not None else None
        return _Seen(view, view.frame, gray, depth, lighting(gray), cal, world)

    def _digest(self, seen: _Seen) -> str:
        """The frame's content digest, computed once per frame and only for frames that
        give a ROI (hashing every frame would cost as much as the rest of a cycle)."""
        key = (seen.view.name, seen.frame.seq)
        if key not in self.digests:
            if len(self.digests) > 64:
                self.digests.clear()
            self.digests[key] = content_digest(seen.gray)
        return self.digests[key]

    def _depth(self, frame: DecodedFrame) -> np.ndarray | None:
        """The frame's recorded depth (metres at its size), or None (the camera's depth
        is not recorded; none for this frame, counted; unusable, counted)."""
        if frame.camera not in self.depth_topics.values():
            return None
        if not self.frames.has_depth(frame.camera, frame.stamp_ns):
            _bump(self.counters, "frame_without_depth")
            return None
        return frame.depth_m

    def _camera_records(self, seen: _Seen, tracks: list[RadarTrack],
                        stamp: int) -> list[RoiRecord]:
        """The ROIs of the tracks the camera sees, and with ground truth the background
        negatives beside its objects."""
        out = []
        positives: list[tuple[RoiRecord, tuple[float, float]]] = []
        for i, track in enumerate(tracks):
            rec = self._track_record(seen, i, track, stamp)
            if rec is None:
                _bump(self.counters, "track_not_visible")
                continue
            out.append(rec)
            if rec.truth == "YES":
                x, y = seen.view.xy[i]
                positives.append((rec, (x, y)))
        if seen.world is not None and positives and self.s.background_per_object > 0:
            out += _background(seen.world, seen.frame.stamp_ns, seen.cal, seen.gray,
                               seen.depth, positives, self.s, self.scorer, self.rng,
                               self.counters, seen.light)
        return out

    def _track_record(self, seen: _Seen, i: int, track: RadarTrack,
                      stamp: int) -> RoiRecord | None:
        """The `i`-th track's ROI in the camera, scored; None when it does not see it."""
        view, frame, cal = seen.view, seen.frame, seen.cal
        roi, column = view.rois[i], view.columns[i]
        if roi is None or column is None:
            return None
        x, y = view.xy[i]
        obs = Observation(seen.gray, roi, column, math.hypot(x, y), seen.depth, cal, (x, y))
        scores = self.scorer.score(obs)
        frame_us = None
        if self.s.timing and (view.name, frame.seq) not in self.timed_frames:
            self.timed_frames.add((view.name, frame.seq))
            frame_us = self.scorer.full_frame_us(seen.gray)
        label, obj_class = (None, "")
        if seen.world is not None:
            label, obj_class = sim_truth.label_track(seen.world, stamp, track.x_m, track.y_m)
        session = self.path.stem
        return RoiRecord(
            id=f"{session}:{stamp}:{view.name}:{track.track_id}", source="recording",
            session=session, frame=f"{view.name}:{frame.seq}", t_ns=stamp, camera=view.name,
            image_w=cal.width, image_h=cal.height, roi=roi, column=column,
            range_m=track.range_m, kind=KIND_TRACK,
            frame_ref=FrameRef("mcap", str(self.path), self.camera_topics[view.name],
                               frame.rx_mono_ns, frame.seq),
            ttc_s=(track.range_m / -track.range_rate_mps
                   if track.range_rate_mps < 0 else None),
            track_id=track.track_id, obj_class=obj_class, truth=label,
            density=self.scorer.density(obs, scores), lighting=seen.light[0],
            frame_median=seen.light[1], has_depth=seen.depth is not None, scores=scores,
            frame_canny_us=frame_us, frame_sha256=self._digest(seen),
            scenario=seen.world.scenario if seen.world is not None else "")


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
                frame_median=light[1], has_depth=depth is not None, scores=scores,
                frame_sha256=pos.frame_sha256, scenario=pos.scenario))
    return out
