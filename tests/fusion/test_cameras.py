"""Several cameras per fusion instance: the combination rule (pure), the core with a rig
of SIMULATED cameras, the shell with one decoder per camera, and the configuration."""

import logging
import subprocess
import sys
import tomllib
from typing import Any

import numpy as np
import pytest

from aeb_radar_camera.common.calibration import Calibration, CalibrationFile
from aeb_radar_camera.common.clock import wall_ns
from aeb_radar_camera.common.config.fusion import FusionConfig
from aeb_radar_camera.common.config.loader import ConfigError, load_config, parse_config
from aeb_radar_camera.common.messages import Decision, Verification, VerifierStatus, encode
from aeb_radar_camera.common.resources import EXAMPLE_CALIBRATION
from aeb_radar_camera.services.fusion.cameras import Camera, CameraView, camera_views, check_track
from aeb_radar_camera.services.fusion.core import FusionCore
from aeb_radar_camera.services.fusion.frames import FrameDecoder
from aeb_radar_camera.services.fusion.main import build_core
from aeb_radar_camera.services.fusion.roi import ColumnGeometry, ColumnProjector, Roi
from aeb_radar_camera.services.fusion.shell import FusionShell
from aeb_radar_camera.services.fusion.verifiers import GateResult, Observation
from aeb_radar_camera.tools.sim.rig import rig_calibration_toml
from tests.fusion.helpers import (
    CAL,
    MS,
    T0,
    FixedVerifier,
    cycle,
    feed,
    frame,
    settings,
    track,
)
from tests.fusion.test_frames import compressed
from tests.fusion.test_shell import FakeBus

ROI = Roi(10, 10, 40, 40)


def view(name: str, sees: bool = True, has_frame: bool = True) -> CameraView:
    """A camera's view of one track (index 0): does it project into the image, is there
    a usable frame (each with its own pixels, so a verifier can tell cameras apart)."""
    gray = np.zeros((480, 848), np.uint8)
    return CameraView(name, frame(gray=gray) if has_frame else None,
                      "" if has_frame else "no camera frame received",
                      [[10.0, 0.0]], [ROI if sees else None], [ROI if sees else None])


class ByCamera:
    """A verifier whose verdict and density depend on the camera (told by the pixels)."""

    def __init__(self, verdicts: dict[int, tuple[bool, float]]) -> None:
        self.verdicts = verdicts       # id(frame.gray) -> (verified, density)
        self.calls: list[int] = []

    def __call__(self, obs: Observation) -> GateResult:
        self.calls.append(id(obs.gray))
        verified, density = self.verdicts[id(obs.gray)]
        return GateResult(density, verified)


def scripted(views: list[CameraView], *verdicts: tuple[bool, float]) -> ByCamera:
    """Verdicts for the views that have a frame, in order."""
    grays = [v.frame.gray for v in views if v.frame is not None]
    return ByCamera({id(g): vd for g, vd in zip(grays, verdicts, strict=True)})


def test_verified_if_any_camera_verifies_and_the_first_that_does_decides():
    views = [view("front"), view("left"), view("right")]
    gate = scripted(views, (False, 0.012), (True, 0.06), (True, 0.09))
    check = check_track(0, views, True, gate)
    assert check.verification is Verification.VERIFIED
    assert check.view is views[1] and check.result is not None and check.result.score == 0.06
    # The camera after the deciding one is not gated: its verdict could not change it.
    assert len(gate.calls) == 2
    assert [(c.camera, c.verification, c.density) for c in check.per_camera] == [
        ("front", Verification.REJECTED, 0.012), ("left", Verification.VERIFIED, 0.06),
        ("right", Verification.NOT_CHECKED, None)]
    assert check.per_camera[0].roi_xywh == tuple(ROI)


def test_rejected_when_every_camera_with_a_frame_that_sees_it_rejects():
    views = [view("front"), view("left", has_frame=False), view("right")]
    gate = scripted(views, (False, 0.010), (False, 0.018))
    check = check_track(0, views, True, gate)
    # The left camera would see it but has no frame: the rejection of the others stands.
    assert check.verification is Verification.REJECTED
    assert check.view is views[2]                       # the closest call: highest density
    assert [c.verification for c in check.per_camera] == [
        Verification.REJECTED, Verification.UNAVAILABLE, Verification.REJECTED]


def test_unavailable_only_if_no_camera_that_would_see_it_has_a_usable_frame():
    views = [view("front", sees=False), view("left", has_frame=False)]
    check = check_track(0, views, True, scripted(views, (True, 0.1)))
    assert check.verification is Verification.UNAVAILABLE and check.view is views[1]
    assert check.roi is None and check.result is None    # no frame: no ROI in it


def test_not_visible_only_if_no_camera_sees_it():
    views = [view("front", sees=False), view("left", sees=False, has_frame=False)]
    check = check_track(0, views, True, scripted(views, (True, 0.1)))
    assert check.verification is Verification.NOT_VISIBLE and check.view is None
    assert [c.verification for c in check.per_camera] == [Verification.NOT_VISIBLE] * 2


def test_not_checked_when_the_gate_is_not_needed():
    views = [view("front", sees=False), view("left")]
    gate = scripted(views, (True, 0.1), (True, 0.1))
    check = check_track(0, views, False, gate)
    assert check.verification is Verification.NOT_CHECKED and check.view is views[1]
    assert gate.calls == [] and check.roi == ROI


def test_one_camera_lists_no_per_camera_checks():
    views = [view("front")]
    assert check_track(0, views, True, scripted(views, (True, 0.1))).per_camera == ()


# -- the core with a rig of simulated cameras -------------------------------------------

RIG = ("front", "left")


def rig_core(verifier, names=RIG, **fusion) -> FusionCore:
    cams = [{"name": n, "calibration": f"rig/{n}.toml"} for n in names]
    s = settings(cameras=cams, **fusion)
    projectors = {n: ColumnProjector(rig_cal(n), ColumnGeometry()) for n in names}
    return FusionCore(s, projectors, verifier)


def rig_cal(name: str) -> Calibration:
    spec = parse_config(tomllib.loads(rig_calibration_toml(name)), CalibrationFile, name)
    return Calibration(spec, name)


AHEAD: dict[str, Any] = dict(x=8.0, y=0.0, vx=-5.0)    # seen by the front camera only
LEFT: dict[str, Any] = dict(x=6.0, y=6.0, vx=-5.0)     # seen by the left camera only (45 deg)


def test_each_track_is_verified_in_the_camera_that_sees_it():
    verifier = FixedVerifier(verdict=True)
    core = rig_core(verifier, gate_scope="all", decision={"corridor": {"enabled": False}})
    res = core.process(cycle(track(1, **AHEAD), track(2, **LEFT)),
                       [feed(frame(seq=11)), feed(frame(seq=22))], T0 + MS, 1)
    ahead, left = res.targets.targets
    assert (ahead.camera, ahead.frame_seq, ahead.verification) == (
        "front", 11, Verification.VERIFIED)
    assert (left.camera, left.frame_seq, left.verification) == ("left", 22,
                                                                Verification.VERIFIED)
    assert [c.verification for c in left.cameras] == [Verification.NOT_VISIBLE,
                                                      Verification.VERIFIED]
    assert left.roi_xywh != () and left.decision is Decision.BRAKE
    assert res.targets.camera == "front,left" and res.targets.cameras_unavailable == {}
    assert res.targets.frames_received == 2
    assert res.command.decision is Decision.BRAKE and res.command.track_id == 1   # most urgent


def test_a_camera_without_frames_leaves_the_others_working_and_is_named():
    verifier = FixedVerifier(verdict=True)
    core = rig_core(verifier, decision={"corridor": {"enabled": False}})
    old = feed(frame(stamp_ns=T0 - 300 * MS))               # left: too old (max 100 ms)
    res = core.process(cycle(track(1, **AHEAD), track(2, **LEFT)), [feed(frame()), old],
                       T0 + MS, 1)
    ahead, left = res.targets.targets
    assert res.targets.verifier_status is VerifierStatus.OK
    assert ahead.verification is Verification.VERIFIED and ahead.decision is Decision.BRAKE
    # Only the left camera would see track 2: unavailable, the default policy warns.
    assert left.verification is Verification.UNAVAILABLE and left.decision is Decision.WARNING
    assert "left: nearest frame -300 ms" in left.reason
    assert list(res.targets.cameras_unavailable) == ["left"]


def test_no_camera_with_a_frame_makes_the_verifier_unavailable_with_every_reason():
    core = rig_core(FixedVerifier(), decision={"corridor": {"enabled": False}})
    res = core.process(cycle(track(1, **AHEAD)), [feed(), feed()], T0 + MS, 1)
    assert res.command.verifier_status is VerifierStatus.UNAVAILABLE
    assert res.targets.unavailable_reason == ("front: no camera frame received; "
                                              "left: no camera frame received")
    assert res.command.decision is Decision.WARNING


def test_a_track_no_camera_sees_is_not_visible():
    # 10 m behind the cameras' fields of view on the right: neither front nor left.
    core = rig_core(FixedVerifier(), decision={"corridor": {"enabled": False}})
    res = core.process(cycle(track(1, x=4.0, y=-9.0, vx=-5.0)), [feed(frame()), feed(frame())],
                       T0 + MS, 1)
    tgt = res.targets.targets[0]
    assert tgt.verification is Verification.NOT_VISIBLE and tgt.camera == ""


def test_the_core_refuses_feeds_that_do_not_match_its_cameras():
    core = rig_core(FixedVerifier())
    with pytest.raises(ValueError, match="1 frame feeds for 2 cameras"):
        core.process(cycle(), feed(), T0, 1)
    with pytest.raises(ValueError, match="projectors"):
        FusionCore(settings(cameras=[{"name": "a", "calibration": "x"}]),
                   {"b": ColumnProjector(rig_cal("front"), ColumnGeometry())}, FixedVerifier())


def test_a_shell_with_two_cameras_decodes_each_and_decides_on_both():
    # One stamp for the frames and the cycle, and a radar age bound no stall on a loaded
    # machine reaches: the test is about the cameras, not the clock.
    core = rig_core(FixedVerifier(verdict=True),
                    decision={"corridor": {"enabled": False}, "radar_max_age_s": 60.0})
    log = logging.getLogger("test")
    decoders = [FrameDecoder(848, 480, log, name) for name in RIG]
    bus = FakeBus()
    shell = FusionShell(bus, core.s, core, decoders, log,  # type: ignore[arg-type]
                      {n: rig_cal(n) for n in RIG})
    stamp = wall_ns()
    decoders[0].decode_now(compressed(stamp_ns=stamp, seq=5), 1)
    decoders[1].decode_now(compressed(stamp_ns=stamp, seq=6), 1)
    decoders[1].decode_now(compressed(stamp_ns=stamp, seq=7, truncate=True), 2)
    res = shell.on_tracks_payload(encode(cycle(track(1, **AHEAD), track(2, **LEFT),
                                              stamp_ns=stamp)), "k", 0)
    assert res is not None
    assert [(t.camera, t.frame_seq) for t in res.targets.targets] == [("front", 5), ("left", 6)]
    assert [name for name, _ in bus.log] == ["fusion_brake_cmd", "fusion_targets"]
    assert res.targets.frames_undecodable == 1
    stats = shell.stats()
    assert stats["frames_unusable"] == 1 and stats["frames_left"] == "0/1/0"


# -- configuration ----------------------------------------------------------------------

def test_a_single_camera_config_reads_as_one_camera_input():
    s = load_config("deploy/fusion.toml", FusionConfig).fusion
    assert s.cameras == ()
    assert [(c.name, c.calibration) for c in s.camera_inputs] == [
        ("front", str(EXAMPLE_CALIBRATION))]


@pytest.mark.parametrize(("fusion", "named"), [
    ({"calibration": "x.toml", "cameras": [{"name": "a", "calibration": "y.toml"}]},
     "not both"),
    ({"cameras": [{"name": "a", "calibration": "y"}, {"name": "a", "calibration": "z"}]},
     "duplicate camera name"),
    ({"cameras": [{"name": "a/b", "calibration": "y"}]}, "cameras[0].name"),
    ({"cameras": [{"name": "a"}]}, "calibration"),
])
def test_invalid_camera_lists_are_refused_naming_the_problem(fusion, named):
    with pytest.raises(ConfigError, match=named.replace("[", r"\[")):
        parse_config({"fusion": fusion}, FusionConfig)


def multicam_config(tmp_path, names=("front", "left", "right")):
    """A fusion TOML with [[fusion.cameras]] and the rig's calibration files."""
    lines = ['[fusion]', 'instance = "multi"']
    for n in names:
        cal = tmp_path / f"{n}.toml"
        cal.write_text(rig_calibration_toml(n))
        lines += ["[[fusion.cameras]]", f'name = "{n}"', f'calibration = "{cal}"']
    path = tmp_path / "fusion.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_multi_camera_config_builds_with_each_calibration(tmp_path):
    cfg = load_config(multicam_config(tmp_path), FusionConfig)
    core, cals = build_core(cfg)
    assert [c.name for c in core.cameras] == list(cals) == ["front", "left", "right"]
    assert cals["left"].spec.name == "synthetic-rig-left"


def test_calibration_override_is_refused_for_several_cameras(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "aeb_radar_camera.services.fusion", "-c",
                           str(multicam_config(tmp_path)), "--calibration", "x.toml"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "with --calibration x.toml" in proc.stderr
    assert "give either frames.camera and calibration (one camera) or [[fusion.cameras]]" \
        in proc.stderr


def test_each_camera_predicts_the_tracks_to_its_own_frame_time():
    geometry = ColumnGeometry(1.8, 1.0, 0)
    cams = [Camera(n, ColumnProjector(CAL, geometry)) for n in "ab"]
    tracks = [track(1, x=12.0, vx=-5.0), track(2, x=20.0, y=1.0)]
    views = camera_views(cams, [feed(frame(T0 + 10 * MS)), feed()], tracks, T0, 50 * MS,
                         True)
    assert views[0].frame is not None and views[1].frame is None
    assert views[0].xy[0] == pytest.approx([12.0 - 5.0 * 0.010, 0.0])   # predicted 10 ms
    assert views[1].xy[0] == [12.0, 0.0]             # no frame: as they are
    assert len(views[0].rois) == len(views[1].rois) == 2
    assert views[1].reason == "no camera frame received"
    # Without alignment (the paper) the newest frame, and no prediction.
    views = camera_views(cams, [feed(frame(T0 + 10 * MS)), feed()], tracks, T0, 50 * MS,
                         False)
    assert views[0].xy[0] == [12.0, 0.0]
