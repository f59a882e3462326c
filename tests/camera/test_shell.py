"""CameraShell.run's exits: a finite source with exit_at_end, and an unusable source."""

import threading

from aeb_radar_camera.common.calibration import Calibration
from aeb_radar_camera.common.config.camera import CameraSettings, FolderSource
from aeb_radar_camera.services.camera.folder import FolderSource as FolderFrames
from aeb_radar_camera.services.camera.shell import CameraShell
from aeb_radar_camera.services.camera.source import Frame, FrameSource, SourceConfigError
from tests.camera.helpers import CALIBRATION, write_folder
from tests.support import open_bus


class Unusable(FrameSource):
    def open(self) -> None:
        raise SourceConfigError("needs a licence dongle")

    def read(self) -> Frame:
        raise AssertionError("never read")


def run_node(router: str, settings: CameraSettings, source: FrameSource) -> tuple[int, CameraShell]:
    cal = Calibration.load(CALIBRATION)
    with open_bus(router, source="camera/front") as bus:
        node = CameraShell(settings, cal, source, bus)
        result: list[int] = []
        thread = threading.Thread(target=lambda: result.append(node.run(threading.Event())))
        thread.start()
        thread.join(60)
        assert result, "CameraShell.run did not return"
        return result[0], node


def test_finite_folder_publishes_every_good_file_then_exits_0(router, tmp_path):
    write_folder(tmp_path, 5, corrupt=("frame2b.jpg",))
    settings = CameraSettings(calibration=CALIBRATION, fps=5.0, exit_at_end=True,
                              info_period_s=0.05, stats_period_s=0,
                              source=FolderSource(path=str(tmp_path), loop=False))
    code, node = run_node(router, settings, FolderFrames(tmp_path, 5.0, loop=False))
    assert code == 0
    info = node.info()
    assert (info.status, info.healthy) == ("end of stream", False)
    # Paced at 5 fps against a ~2 ms encoder: nothing dropped, and the last frame is
    # flushed before the exit.
    assert (info.frames_captured, info.frames_published, info.frames_dropped) == (5, 5, 0)
    assert info.errors == {"unreadable_input": 1}


def test_an_unusable_source_exits_2(router):
    settings = CameraSettings(calibration=CALIBRATION, info_period_s=0.05, stats_period_s=0)
    code, node = run_node(router, settings, Unusable())
    assert code == 2
    assert str(node.pipeline.fatal) == "needs a licence dongle"


class DepthFrames(FrameSource):
    """`n` frames with depth (frame i: grey 20 i, depth 1000 + i mm), then the end."""

    kind = "depth-test"

    def __init__(self, width: int, height: int, n: int) -> None:
        super().__init__()
        self.size, self.n, self.i = (width, height), n, 0

    def read(self) -> Frame:
        import numpy as np

        from aeb_radar_camera.services.camera.source import EndOfStream

        if self.i >= self.n:
            raise EndOfStream("done")
        w, h = self.size
        self.i += 1
        return Frame(np.full((h, w, 3), 20 * self.i, np.uint8), 5_000 + self.i,
                     np.full((h, w), 1000 + self.i, np.uint16))


def test_a_source_with_depth_gets_it_published_beside_each_frame(router):
    import numpy as np

    from aeb_radar_camera.common.depth_image import decode_depth
    from aeb_radar_camera.common.keys import CAMERA_DEPTH, CAMERA_JPEG
    from tests.support import Collector, wait_for

    cal = Calibration.load(CALIBRATION)
    settings = CameraSettings(calibration=CALIBRATION, fps=1000.0, exit_at_end=True,
                              info_period_s=0.05, stats_period_s=0)
    jpegs, depths = Collector(), Collector()
    with open_bus(router, source="test") as watcher:
        watcher.subscribe(CAMERA_JPEG, jpegs, camera="front")
        watcher.subscribe(CAMERA_DEPTH, depths, camera="front")
        code, node = run_node(router, settings, DepthFrames(cal.width, cal.height, 6))
        assert code == 0
        info = node.info()
        assert info.frames_published >= 1 and info.depth_published == info.frames_published
        wait_for(lambda: len(depths.messages) == info.depth_published
                 and len(jpegs.messages) == info.frames_published, 30, what="all received")
    frame_stamps = {m.header.stamp_ns for m in jpegs.messages}
    for d in depths.messages:
        assert d.header.stamp_ns in frame_stamps
        assert (d.width, d.height) == (cal.width // 2, cal.height // 2)   # decimation 2
        units = decode_depth(d.data, d.codec, d.width, d.height)
        assert np.all(units == 1000 + d.header.stamp_ns - 5_000)
