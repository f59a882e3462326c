"""The capture/publish threads: no backlog behind a slow bus, reopen with backoff,
end of stream, unusable sources. Driven by a scripted source (no real time)."""

import queue
import threading
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from aeb_radar_camera.common.imaging import decode_gray
from aeb_radar_camera.common.messages import CompressedFrame
from aeb_radar_camera.services.camera.core import Backoff, CameraCore, Health
from aeb_radar_camera.services.camera.pipeline import FramePipeline
from aeb_radar_camera.services.camera.source import (
    EndOfStream,
    Frame,
    FrameSource,
    SourceConfigError,
    SourceError,
)
from tests.support import wait_for

W, H = 32, 24


class ScriptedSource(FrameSource):
    """read() returns (or raises) what the test puts in `script`; open() likewise
    raises the exceptions queued in `open_errors`."""

    kind = "scripted"

    def __init__(self) -> None:
        super().__init__()
        self.script: queue.Queue[Frame | BaseException] = queue.Queue()
        self.open_errors: list[BaseException] = []
        self.opens = 0
        self.closes = 0
        self.abort = threading.Event()

    def open(self) -> None:
        self.opens += 1
        if self.open_errors:
            raise self.open_errors.pop(0)

    def read(self) -> Frame:
        """Blocks until the test scripts something, or `abort` (a device timing out)."""
        while True:
            try:
                item = self.script.get(timeout=0.02)
                break
            except queue.Empty:
                if self.abort.is_set():
                    raise SourceError("scripted: aborted") from None
        if isinstance(item, BaseException):
            raise item
        return item

    def close(self) -> None:
        self.closes += 1

    def push(self, n: int, start: int = 0) -> None:
        for i in range(start, start + n):
            self.script.put(Frame(np.full((H, W, 3), i % 256, np.uint8), stamp_ns=1000 + i))


class GatedBus:
    """A publish callable that blocks while `gate` is clear (a congested bus)."""

    def __init__(self) -> None:
        self.gate = threading.Event()
        self.entered = threading.Event()
        self.messages: list[CompressedFrame] = []

    def __call__(self, msg: CompressedFrame) -> None:
        self.entered.set()
        self.gate.wait(30)
        self.messages.append(msg)


@contextmanager
def running(pipe: FramePipeline, src: ScriptedSource) -> Iterator[FramePipeline]:
    pipe.start()
    try:
        yield pipe
    finally:
        src.abort.set()
        pipe.stop()


def make(source: FrameSource, publish, fps: float = 1e9) -> FramePipeline:
    """A pipeline whose rate gate never decimates (the test decides what arrives when)."""
    return FramePipeline(source, CameraCore("front", W, H, fps), Health(stall_timeout_s=5.0),
                         Backoff(0.01, 0.02), publish=publish, jpeg_quality=80)


def test_a_blocked_bus_drops_frames_and_then_publishes_the_newest():
    src = ScriptedSource()
    bus = GatedBus()
    pipe = make(src, bus)
    try:
        with running(pipe, src):
            src.push(1)
            assert bus.entered.wait(30)          # frame 0 is stuck in the bus
            src.push(9, start=1)                 # frames 1..9 arrive meanwhile
            wait_for(lambda: pipe.core.stats.captured == 10, 30, what="10 captured")
            bus.gate.set()
            wait_for(lambda: len(bus.messages) == 2, 30, what="2 published")
            wait_for(lambda: pipe.core.pending is None, 30)
            assert [m.header.stamp_ns for m in bus.messages] == [1000, 1009]
            assert [m.header.seq for m in bus.messages] == [0, 1]
            assert pipe.core.stats.dropped == 8
            assert pipe.core.stats.published == 2
            # The published JPEG holds the frame's pixels (all 9).
            assert abs(int(decode_gray(bus.messages[1].jpeg, W, H).mean()) - 9) <= 1
    finally:
        bus.gate.set()


def test_a_failing_source_is_reported_and_reopened_with_backoff():
    src = ScriptedSource()
    published: list[CompressedFrame] = []
    pipe = make(src, published.append)
    src.open_errors = [SourceError("no device")]

    def push_one(i: int) -> None:
        src.push(1, start=i)
        wait_for(lambda: len(published) == i + 1, 30, what=f"frame {i} published")

    with running(pipe, src):
        wait_for(lambda: src.opens == 2, 30, what="second open")
        for i in range(3):
            push_one(i)
        src.open_errors = [SourceError("still gone")]
        src.script.put(SourceError("unplugged"))
        wait_for(lambda: src.opens == 4, 30, what="reopened twice")
        for i in range(3, 5):
            push_one(i)
        with pipe.lock:
            assert pipe.health.reopens == 1
            assert pipe.core.stats.errors.get("source_error") == 3
            assert pipe.health.status(pipe.health.last_frame_mono_ns or 0) == (True, "")
        assert src.closes == 1
        assert [m.header.seq for m in published] == [0, 1, 2, 3, 4]
        assert [m.header.stamp_ns for m in published] == [1000, 1001, 1002, 1003, 1004]


def test_status_names_the_failure_while_reopening():
    src = ScriptedSource()
    src.open_errors = [SourceError("camera unplugged")]
    pipe = FramePipeline(src, CameraCore("front", W, H, 30.0), Health(1.0),
                         Backoff(30.0, 30.0), publish=lambda m: None)
    with running(pipe, src):
        def status() -> str:
            with pipe.lock:
                return pipe.health.status(0)[1]
        wait_for(lambda: "camera unplugged" in status(), 30)
        assert status() == "source failed (open: camera unplugged); reopening in 30.0 s"


def test_end_of_stream_flushes_the_last_frame_and_finishes():
    src = ScriptedSource()
    bus = GatedBus()
    pipe = make(src, bus)
    try:
        with running(pipe, src):
            src.push(1)
            assert bus.entered.wait(30)
            src.push(1, start=1)
            src.script.put(EndOfStream("done"))
            wait_for(lambda: pipe.finished, 30, what="end of stream")
            bus.gate.set()
            wait_for(lambda: len(bus.messages) == 2, 30, what="pending frame published")
            assert pipe.ended.is_set() and pipe.fatal is None
            with pipe.lock:
                assert pipe.health.status(0) == (False, "end of stream")
        assert src.closes == 1
    finally:
        bus.gate.set()


def test_an_unusable_source_is_never_retried():
    bad = ScriptedSource()
    bad.open_errors = [SourceConfigError("pyrealsense2 missing")]
    pipe = make(bad, lambda m: None)
    with running(pipe, bad):
        wait_for(lambda: pipe.finished, 30, what="fatal")
    assert str(pipe.fatal) == "pyrealsense2 missing"
    assert bad.opens == 1


def test_frames_of_the_wrong_size_are_never_published():
    src = ScriptedSource()
    published: list[CompressedFrame] = []
    pipe = make(src, published.append)
    with running(pipe, src):
        src.script.put(Frame(np.zeros((H, W + 1, 3), np.uint8), stamp_ns=1))
        src.push(1, start=5)
        wait_for(lambda: len(published) == 1, 30)
        assert published[0].header.stamp_ns == 1005
        assert pipe.core.stats.errors.get("size_mismatch") == 1


def test_a_bug_in_a_source_is_reported_as_the_source_down_and_the_capture_goes_on():
    src = ScriptedSource()
    published: list[CompressedFrame] = []
    pipe = make(src, published.append)
    with running(pipe, src):
        src.script.put(KeyError("plugin bug"))
        wait_for(lambda: src.opens == 2, 30, what="reopened after the bug")
        with pipe.lock:
            assert pipe.core.stats.errors.get("source_error") == 1
            assert "read: 'plugin bug'" in pipe.health.error
        src.push(1)
        wait_for(lambda: len(published) == 1, 30, what="frame after the reopen")


def depth_of(i: int, h: int = H, w: int = W) -> np.ndarray:
    return (np.arange(h * w, dtype=np.uint16).reshape(h, w) + 100 * i).astype(np.uint16)


def test_depth_goes_out_beside_its_frame_decimated_lossless_and_a_bad_one_is_counted():
    from aeb_radar_camera.common.config.camera import DepthSettings
    from aeb_radar_camera.common.depth_image import decode_depth

    src = ScriptedSource()
    frames: list[CompressedFrame] = []
    depths: list = []
    pipe = FramePipeline(src, CameraCore("front", W, H, 1e9), Health(stall_timeout_s=5.0),
                         Backoff(0.01, 0.02), publish=frames.append,
                         publish_depth=depths.append, depth=DepthSettings(decimation=2))
    with running(pipe, src):
        img = np.zeros((H, W, 3), np.uint8)
        script = [depth_of(0), None, depth_of(2, H // 2, W),     # none; wrong size
                  depth_of(3).astype(np.float32)]                   # not uint16
        for i, depth in enumerate(script):
            src.script.put(Frame(img, 1000 + i, depth))
            # One at a time: a frame waiting in the slot would be replaced by the next.
            n = i + 1
            wait_for(lambda: len(frames) == n and pipe.core.pending is None, 30,  # noqa: B023
                     what=f"frame {i} published")
        wait_for(lambda: pipe.core.stats.errors.snapshot().get("depth_error") == 2, 30)
    assert len(depths) == 1 and pipe.core.stats.depth_published == 1
    d = depths[0]
    assert d.header.stamp_ns == frames[0].header.stamp_ns == 1000
    assert (d.camera, d.width, d.height, d.codec, d.units_m) == ("front", W // 2, H // 2,
                                                                  "zstd", 0.001)
    assert np.array_equal(decode_depth(d.data, d.codec, d.width, d.height),
                          depth_of(0)[::2, ::2])
    assert [f.header.stamp_ns for f in frames] == [1000, 1001, 1002, 1003]


def test_depth_is_thinned_to_its_own_rate():
    core = CameraCore("front", W, H, 30.0, depth_fps=10.0)
    period = 1_000_000_000 // 30
    due = [core.depth_due(i * period) for i in range(9)]
    assert due == [True, False, False] * 3
    assert all(CameraCore("front", W, H, 30.0).depth_due(i * period) for i in range(9))
