"""Frame sources: image folder, OpenCV capture on a video file, synthetic plugins,
RealSense (the wrapper, against a stand-in for pyrealsense2: no camera on CI)."""

import sys
import types

import cv2
import numpy as np
import pytest

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.config.camera import CameraConfig
from aeb_radar_camera.common.config.loader import parse_config
from aeb_radar_camera.services.camera.folder import FolderSource, natural_key
from aeb_radar_camera.services.camera.opencv_capture import OpenCVSource
from aeb_radar_camera.services.camera.plugin import PluginContext, load_factory
from aeb_radar_camera.services.camera.realsense import RealSenseSource, import_pyrealsense2
from aeb_radar_camera.services.camera.registry import build_source
from aeb_radar_camera.services.camera.source import (
    EndOfStream,
    Frame,
    FrameSource,
    Pacer,
    SourceConfigError,
    SourceError,
)
from aeb_radar_camera.tools.sim.moving_box import MovingBoxSource
from tests.camera.helpers import CALIBRATION, write_folder


class FakeTime:
    """A monotonic clock that only moves when someone sleeps (records the sleeps)."""

    def __init__(self) -> None:
        self.now = 100.0
        self.sleeps: list[float] = []

    def clock(self) -> float:
        return self.now

    def sleep(self, s: float) -> None:
        self.sleeps.append(s)
        self.now += s

    def wall_ns(self) -> int:
        return round(self.now * 1e9)


def read_all(source: FrameSource, limit: int = 100) -> list[Frame]:
    frames: list[Frame] = []
    source.open()
    try:
        while len(frames) < limit:
            frames.append(source.read())
    except EndOfStream:
        pass
    finally:
        source.close()
    return frames


def folder(tmp_path, fake: FakeTime, loop: bool, fps: float = 10.0) -> FolderSource:
    return FolderSource(tmp_path, fps, loop=loop, extensions=(".jpg", ".png"),
                        clock=fake.clock, sleep=fake.sleep, wall_clock=fake.wall_ns)


# ---- pacing ----

def test_pacer_keeps_a_fixed_grid_and_does_not_burst_after_a_stall():
    fake = FakeTime()
    pacer = Pacer(10.0, fake.clock, fake.sleep)
    pacer.wait()
    fake.now += 0.03                      # work took 30 ms: sleep the remaining 70
    pacer.wait()
    assert fake.sleeps == [pytest.approx(0.07)]
    fake.now += 0.5                       # a long stall: restart the grid, no catch-up
    pacer.wait()
    pacer.wait()
    assert fake.sleeps[1:] == [pytest.approx(0.1)]


# ---- image folder ----

def test_folder_natural_order_pacing_and_skipped_unreadable_files(tmp_path):
    good = write_folder(tmp_path, 11, width=64, height=48,
                        corrupt=("frame3b.jpg", "frame7b.png"))
    (tmp_path / "readme.txt").write_text("not an image, not listed")
    fake = FakeTime()
    src = folder(tmp_path, fake, loop=False)
    frames = read_all(src)

    # frame10 after frame9 (natural order), both bad files skipped and counted.
    assert [p.name for p in src.files][-3:] == ["frame8.jpg", "frame9.jpg", "frame10.jpg"]
    assert len(frames) == 11
    for f, path in zip(frames, good, strict=True):
        want = cv2.imread(str(path))
        assert want is not None
        assert f.image.shape == (48, 64, 3) and f.image.dtype == np.uint8
        assert np.abs(f.image.astype(int) - want.astype(int)).max() <= 2
    assert src.skipped == 2
    # Paced at 10 fps: one 100 ms slot per frame, stamped with the delivery time.
    stamps = np.array([f.stamp_ns for f in frames])
    np.testing.assert_allclose(np.diff(stamps), 100_000_000, atol=1_000)


def test_folder_loops_and_counts_unreadable_files_on_every_pass(tmp_path):
    write_folder(tmp_path, 3, width=64, height=48, corrupt=("frame1b.jpg",))
    fake = FakeTime()
    src = folder(tmp_path, fake, loop=True)
    frames = read_all(src, limit=7)
    first = [f.image for f in frames[:3]]
    for i, f in enumerate(frames[3:6]):
        assert np.array_equal(f.image, first[i])
    assert src.skipped == 2   # the bad file, once per completed pass


def test_folder_errors_are_source_errors(tmp_path):
    fake = FakeTime()
    with pytest.raises(SourceError, match="does not exist"):
        folder(tmp_path / "missing", fake, loop=True).open()
    with pytest.raises(SourceError, match="no image files"):
        folder(tmp_path, fake, loop=True).open()
    write_folder(tmp_path, 0, corrupt=("a.jpg", "b.png"))
    src = folder(tmp_path, fake, loop=True)
    src.open()
    with pytest.raises(SourceError, match="no readable image"):
        src.read()
    assert src.skipped == 2


def test_natural_key_orders_numbers_by_value():
    names = ["f10.jpg", "f2.jpg", "F1.jpg", "f2b.jpg", "g.jpg"]
    assert sorted(names, key=natural_key) == ["F1.jpg", "f2.jpg", "f2b.jpg", "f10.jpg", "g.jpg"]


# ---- OpenCV capture ----

def write_video(path, n: int, fps: float = 25.0, w: int = 64, h: int = 48) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), fps, (w, h))
    assert writer.isOpened()
    for i in range(n):
        img = np.zeros((h, w, 3), np.uint8)
        img[:, : (i + 1) * 4] = 255           # a bar that grows one step per frame
        writer.write(img)
    writer.release()


def bar_length(image: np.ndarray) -> int:
    return int((image[:, :, 1].mean(axis=0) > 128).sum())


def test_opencv_video_file_plays_in_order_at_its_rate_and_ends(tmp_path):
    path = tmp_path / "clip.avi"
    write_video(path, 6, fps=25.0)
    fake = FakeTime()
    src = OpenCVSource(str(path), clock=fake.clock, sleep=fake.sleep, wall_clock=fake.wall_ns)
    frames = read_all(src)
    assert [bar_length(f.image) for f in frames] == [4, 8, 12, 16, 20, 24]
    np.testing.assert_allclose(np.diff([f.stamp_ns for f in frames]), 40_000_000, atol=1_000)
    assert "file" in src.describe() and "25 fps" in src.describe()


def test_opencv_video_file_loops_and_configured_fps_wins(tmp_path):
    path = tmp_path / "clip.avi"
    write_video(path, 3)
    fake = FakeTime()
    src = OpenCVSource(str(path), fps=5.0, loop=True, clock=fake.clock, sleep=fake.sleep,
                       wall_clock=fake.wall_ns)
    frames = read_all(src, limit=7)
    assert [bar_length(f.image) for f in frames] == [4, 8, 12, 4, 8, 12, 4]
    np.testing.assert_allclose(np.diff([f.stamp_ns for f in frames]), 200_000_000, atol=1_000)


def test_opencv_missing_device_is_a_source_error(tmp_path):
    src = OpenCVSource(str(tmp_path / "no-such-device"), timeout_ms=100)
    with pytest.raises(SourceError, match="cannot open"):
        src.open()
    with pytest.raises(ValueError, match="unknown OpenCV backend"):
        OpenCVSource("0", backend="directshow-on-linux")


# ---- synthetic plugins ----

def camera_config(source: dict) -> CameraConfig:
    return parse_config({"camera": {"calibration": CALIBRATION, "fps": 50.0, "source": source}},
                        CameraConfig, "test")


def test_builtin_synthetic_scene_through_config_is_deterministic_and_finite():
    cfg = camera_config({"kind": "synthetic", "options": {"frames": 3, "speed_mps": 5.0}})
    src = build_source(cfg.camera, Calibration.load(CALIBRATION))
    assert isinstance(src, MovingBoxSource) and src.fps == 50.0
    frames = read_all(src)
    assert len(frames) == 3
    assert frames[0].image.shape == (480, 848, 3)
    assert not np.array_equal(frames[0].image, frames[1].image)   # the box moved
    assert np.array_equal(src.render(1), frames[1].image)


class RecordingSource(FrameSource):
    kind = "test-plugin"

    def __init__(self, context: PluginContext) -> None:
        super().__init__()
        self.context = context

    def read(self) -> Frame:
        raise EndOfStream


def make_recording_source(context: PluginContext) -> RecordingSource:
    return RecordingSource(context)


def not_a_source(context: PluginContext) -> object:
    return "a string"


def picky(context: PluginContext) -> FrameSource:
    raise ValueError(f"unknown scenario {context.options.get('scenario')!r}")


NOT_CALLABLE = 42


def test_plugin_factory_gets_the_camera_context():
    cfg = camera_config({"kind": "synthetic", "fps": 15.0,
                         "factory": "tests.camera.test_sources:make_recording_source",
                         "options": {"scenario": "cut_in"}})
    cal = Calibration.load(CALIBRATION)
    src = build_source(cfg.camera, cal)
    assert isinstance(src, RecordingSource)
    ctx = src.context
    assert (ctx.width, ctx.height, ctx.fps, ctx.camera) == (848, 480, 15.0, "front")
    assert ctx.options == {"scenario": "cut_in"} and ctx.calibration is cal


@pytest.mark.parametrize(
    ("factory", "says"),
    [
        ("tests.camera.no_such_module:make", "cannot import module 'tests.camera.no_such_module'"),
        ("tests.camera.test_sources:missing", "has no attribute 'missing'"),
        ("tests.camera.test_sources:NOT_CALLABLE", "'NOT_CALLABLE' is not callable"),
        ("tests.camera.test_sources:not_a_source", "returned str, not a FrameSource"),
        ("tests.camera.test_sources:picky", "rejected its options: unknown scenario 'x'"),
    ],
)
def test_bad_plugin_is_a_clear_config_error(factory, says):
    cfg = camera_config({"kind": "synthetic", "factory": factory, "options": {"scenario": "x"}})
    with pytest.raises(SourceConfigError, match="synthetic factory") as err:
        build_source(cfg.camera, Calibration.load(CALIBRATION))
    assert says in str(err.value)


def test_factory_path_format_is_checked_at_config_load_and_by_the_loader():
    from aeb_radar_camera.common.config.loader import ConfigError

    with pytest.raises(ConfigError, match=r"\$\.camera\.source\.factory"):
        camera_config({"kind": "synthetic", "factory": "no_colon_here"})
    with pytest.raises(SourceConfigError, match=r"expected 'package\.module:callable'"):
        load_factory("no_colon_here")
    with pytest.raises(SourceConfigError, match="unknown options"):
        build_source(camera_config({"kind": "synthetic", "options": {"colour": "red"}}).camera,
                     Calibration.load(CALIBRATION))


# ---- RealSense ----

def test_missing_pyrealsense2_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyrealsense2", None)   # import fails as if absent
    with pytest.raises(SourceConfigError, match=r"pip install 'aeb-radar-camera\[realsense\]'"):
        import_pyrealsense2()
    with pytest.raises(SourceConfigError, match="pyrealsense2"):
        RealSenseSource().open()


class FakeColorFrame:
    def __init__(self, data: np.ndarray, fmt: str, stamp_ms: float, domain: str) -> None:
        self._data, self._fmt, self._stamp, self._domain = data, fmt, stamp_ms, domain

    def __bool__(self) -> bool:
        return True

    def get_data(self) -> np.ndarray:
        return self._data

    def get_profile(self):
        return types.SimpleNamespace(format=lambda: self._fmt)

    def get_timestamp(self) -> float:
        return self._stamp

    def get_frame_timestamp_domain(self) -> str:
        return self._domain


class FakeDepthFrame:
    def __init__(self, data: np.ndarray) -> None:
        self._data = data

    def __bool__(self) -> bool:
        return True

    def get_data(self) -> np.ndarray:
        return self._data


def fake_rs(frames: list, stopped_after: bool = False, serials: tuple[str, ...] = ("123",),
            depths: list | None = None, depth_scale: float = 0.001,
            start_fails_with_depth: bool = False):
    """A stand-in for the parts of pyrealsense2 the source uses: records the calls.
    `depths`: the depth frame of each frameset (None: none); `align` records that it ran."""
    calls: list = []
    depths = list(depths or [])

    def device(serial: str):
        return types.SimpleNamespace(get_info=lambda what: serial)

    def context():
        return types.SimpleNamespace(query_devices=lambda: [device(s) for s in serials])

    sensor = types.SimpleNamespace(get_depth_scale=lambda: depth_scale)

    class Pipeline:
        def start(self, config):
            calls.append(("start", config.calls))
            if start_fails_with_depth and any(c[1][:1] == ("depth",) for c in config.calls):
                raise RuntimeError("no depth stream in this recording")
            device = types.SimpleNamespace(as_playback=lambda: playback,
                                           first_depth_sensor=lambda: sensor)
            return types.SimpleNamespace(get_device=lambda: device)

        def wait_for_frames(self, timeout_ms):
            if not frames:
                raise RuntimeError(f"Frame didn't arrive within {timeout_ms}")
            color = frames.pop(0)
            depth = depths.pop(0) if depths else None
            return types.SimpleNamespace(get_color_frame=lambda: color,
                                         get_depth_frame=lambda: depth, aligned=False)

        def stop(self):
            calls.append(("stop",))

    class Align:
        def __init__(self, to):
            calls.append(("align", to))

        def process(self, frameset):
            frameset.aligned = True
            calls.append(("aligned",))
            return frameset

    class Config:
        def __init__(self):
            self.calls = []

        def __getattr__(self, name):
            return lambda *a, **k: self.calls.append((name, a, k))

    playback = types.SimpleNamespace(
        set_real_time=lambda v: calls.append(("real_time", v)),
        current_status=lambda: "stopped" if stopped_after else "playing")
    rs = types.SimpleNamespace(
        pipeline=Pipeline, config=Config, context=context, align=Align,
        camera_info=types.SimpleNamespace(serial_number="serial_number"),
        stream=types.SimpleNamespace(color="color", depth="depth"),
        format=types.SimpleNamespace(bgr8="bgr8", rgb8="rgb8", bgra8="bgra8", rgba8="rgba8",
                                     yuyv="yuyv", z16="z16"),
        timestamp_domain=types.SimpleNamespace(global_time="global", system_time="system",
                                               hardware_clock="hw"),
        playback_status=types.SimpleNamespace(stopped="stopped"))
    return rs, calls


def test_realsense_device_stream_frames_stamps_and_timeout():
    now_ns = 1_700_000_000_000_000_000
    bgr = np.zeros((480, 848, 3), np.uint8)
    bgr[..., 2] = 200
    rgb = bgr[..., ::-1].copy()
    frames = [FakeColorFrame(bgr, "bgr8", now_ns / 1e6 - 30, "global"),
              FakeColorFrame(rgb, "rgb8", 12.5, "hw"),
              FakeColorFrame(bgr, "bgr8", now_ns / 1e6 - 5000, "system")]
    rs, calls = fake_rs(frames)
    src = RealSenseSource(serial="123", loader=lambda: rs, wall_clock=lambda: now_ns)
    src.open()
    start = calls[0][1]
    assert ("enable_device", ("123",), {}) in start
    assert ("enable_stream", ("color", 848, 480, "bgr8", 30), {}) in start
    a, b, c = src.read(), src.read(), src.read()
    # device capture time (global clock); a double in ms holds it to a microsecond
    assert a.stamp_ns == pytest.approx(now_ns - 30_000_000, abs=1_000)
    assert b.stamp_ns == now_ns                    # hardware clock: arrival time
    assert c.stamp_ns == now_ns                    # 5 s off the host clock: arrival time
    assert np.array_equal(b.image, bgr)            # RGB converted to BGR
    assert a.image is not bgr                      # copied out of librealsense's buffer
    with pytest.raises(SourceError, match="no frame within 1000 ms"):
        src.read()
    src.close()
    src.close()
    assert calls.count(("stop",)) == 1


@pytest.mark.parametrize(("serials", "wanted", "message"), [
    ((), "", "no RealSense device connected"),
    (("999",), "123", r"RealSense 123 not connected \(connected: 999\)"),
])
def test_realsense_missing_device_fails_at_once_without_starting(serials, wanted, message):
    # pipeline.start() would block for 15 s holding the GIL: it must not be reached.
    rs, calls = fake_rs([], serials=serials)
    src = RealSenseSource(serial=wanted, loader=lambda: rs)
    with pytest.raises(SourceError, match=message):
        src.open()
    assert not [c for c in calls if c[0] == "start"]


def test_realsense_bag_plays_in_real_time_and_ends():
    img = np.zeros((480, 848, 3), np.uint8)
    rs, calls = fake_rs([FakeColorFrame(img, "bgr8", 1.0, "hw")], stopped_after=True)
    src = RealSenseSource(bag="drive.bag", loader=lambda: rs, wall_clock=lambda: 42)
    src.open()
    assert ("enable_device_from_file", ("drive.bag",), {"repeat_playback": False}) in calls[0][1]
    assert ("real_time", True) in calls
    assert src.read().stamp_ns == 42
    with pytest.raises(EndOfStream):
        src.read()
    src.close()


def test_realsense_depth_is_aligned_to_colour_and_delivered_in_millimetres():
    img = np.zeros((480, 848, 3), np.uint8)
    raw = np.full((480, 848), 4000, np.uint16)
    raw[0, 0] = 0
    rs, calls = fake_rs([FakeColorFrame(img, "bgr8", 1.0, "hw")] * 2,
                        depths=[FakeDepthFrame(raw), None])
    src = RealSenseSource(loader=lambda: rs, wall_clock=lambda: 7)
    src.open()
    start = calls[0][1]
    assert ("enable_stream", ("depth", 848, 480, "z16", 30), {}) in start
    assert ("align", "color") in calls
    got = src.read()
    assert ("aligned",) in calls
    assert got.depth is not None and got.depth.dtype == np.uint16
    assert np.array_equal(got.depth, raw) and got.depth is not raw   # copied out
    assert src.read().depth is None                # a frameset without depth
    src.close()
    # A device whose depth unit is 0.1 mm: converted to mm; colour only when asked.
    rs, calls = fake_rs([FakeColorFrame(img, "bgr8", 1.0, "hw")],
                        depths=[FakeDepthFrame(raw)], depth_scale=0.0001)
    src = RealSenseSource(loader=lambda: rs)
    src.open()
    depth = src.read().depth
    assert depth is not None and depth[1, 1] == 400 and depth[0, 0] == 0
    rs, calls = fake_rs([FakeColorFrame(img, "bgr8", 1.0, "hw")])
    src = RealSenseSource(loader=lambda: rs, depth=False)
    src.open()
    assert src.read().depth is None and not [c for c in calls if c[0] == "align"]
    assert not [c for c in calls[0][1] if c[1][:1] == ("depth",)]


def test_a_recording_without_depth_plays_colour_only():
    img = np.zeros((480, 848, 3), np.uint8)
    rs, calls = fake_rs([FakeColorFrame(img, "bgr8", 1.0, "hw")],
                        start_fails_with_depth=True)
    src = RealSenseSource(bag="colour.bag", loader=lambda: rs)
    src.open()
    assert len([c for c in calls if c[0] == "start"]) == 2
    frame = src.read()
    assert frame.depth is None and frame.image.shape == (480, 848, 3)
