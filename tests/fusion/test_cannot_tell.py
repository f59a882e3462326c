"""A threat the camera cannot tell yet (`[fusion.decision.kinematic]
cannot_tell_full_only`): WARNING up to the full stage, BRAKE at full level from it; a
threat the camera (or the track's evidence) confirms keeps every stage; the paper's
profile is untouched."""

from pathlib import Path

import pytest

from aeb_radar_camera.common.config.fusion import FusionConfig, KinematicSettings
from aeb_radar_camera.common.config.loader import ConfigError, load_config
from aeb_radar_camera.common.messages import Decision, Verification
from aeb_radar_camera.services.fusion.decision import required_decel
from aeb_radar_camera.services.fusion.verifiers import GateResult, Observation, ParamValue
from tests.fusion.helpers import FixedVerifier, make_core, settings
from tests.fusion.test_decision_kinematic import Drive, ahead, track

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
V50 = 50 / 3.6
CANNOT_TELL = {"rule": "kinematic", "kinematic": {"cannot_tell_full_only": True,
                                                  "cannot_tell_decel_mps2": 5.5}}


class Script:
    """A recall_first-like verifier: the llr of a script per call, unverifiable where the
    script says None (depth too sparse to tell)."""

    name = "script"
    needs_depth = False
    gives_llr = True

    def __init__(self, *llrs: float | None) -> None:
        self.llrs = list(llrs)

    def params(self) -> dict[str, ParamValue]:
        return {}

    def verify(self, obs: Observation) -> GateResult:
        llr = self.llrs.pop(0) if len(self.llrs) > 1 else self.llrs[0]
        if llr is None:
            return GateResult(0.0, False, {"llr": 0.0, "depth_sparse": 1.0}, "llr",
                              unverifiable=True)
        return GateResult(llr, llr >= 0, {"llr": llr}, "llr")


def staged(x: float) -> tuple[Decision, float]:
    """What the kinematic rule asks for a stationary target x m ahead at 50 km/h."""
    need = required_decel(x - 1.0, V50, 0.0, 0.0, 0.45)
    ttc = x / V50
    if need >= 4.5 or ttc < 1.6:
        return Decision.BRAKE, 100.0
    if need >= 3.0 or ttc < 2.2:
        return Decision.BRAKE, 50.0
    if need >= 2.0 or ttc < 3.0:
        return Decision.WARNING, 0.0
    return Decision.NONE, 0.0


@pytest.mark.parametrize("x", [60.0, 45.0, 38.0, 32.0, 28.0, 26.0, 24.0, 20.0])
def test_a_cannot_tell_threat_warns_before_the_full_stage_and_brakes_at_it(x):
    d = Drive(make_core(Script(None), decision=CANNOT_TELL))
    res = d.step(V50, ahead(x, V50))
    tgt = res.targets.targets[0]
    need = required_decel(x - 1.0, V50, 0.0, 0.0, 0.45)
    if need >= 5.5 or x / V50 < 1.6:
        expected = (Decision.BRAKE, 100.0)
        assert "camera cannot tell, full stage" in tgt.reason
    elif staged(x)[0] is not Decision.NONE:
        expected = (Decision.WARNING, 0.0)       # the partial brake suppressed too
        assert "camera cannot tell, warning until the full stage" in tgt.reason
    else:
        expected = (Decision.NONE, 0.0)
    assert (res.command.decision, res.command.brake_level_pct) == expected
    assert tgt.verification is Verification.UNAVAILABLE
    assert tgt.gate_detail["cannot_tell"] == 1.0 and tgt.gate_detail["evidence_llr"] == 0.0


def test_the_cases_above_cover_a_suppressed_partial_and_a_full_brake_with_warning_before():
    # 38 m: the staged rule's partial brake (3.6 m/s^2); 24 m: beyond 5.5 m/s^2.
    assert staged(38.0) == (Decision.BRAKE, 50.0)
    assert staged(28.0) == (Decision.BRAKE, 100.0)
    assert required_decel(27.0, V50, 0.0, 0.0, 0.45) < 5.5
    assert required_decel(23.0, V50, 0.0, 0.0, 0.45) >= 5.5


@pytest.mark.parametrize("x", [60.0, 45.0, 38.0, 32.0, 28.0, 20.0])
def test_a_confirmed_threat_is_staged_as_before(x):
    d = Drive(make_core(FixedVerifier(verdict=True), decision=CANNOT_TELL))
    res = d.step(V50, ahead(x, V50))
    assert (res.command.decision, res.command.brake_level_pct) == staged(x)
    assert "cannot_tell" not in res.targets.targets[0].gate_detail


def test_evidence_that_confirmed_the_track_keeps_it_staged_through_sparse_frames():
    # Confirmed once (depth saw a surface at the range), then depth too sparse: the
    # track's evidence decides, every stage as for a confirmed threat.
    d = Drive(make_core(Script(1.5, None), decision=CANNOT_TELL))
    first = d.step(V50, ahead(60.0, V50))
    assert first.targets.targets[0].gate_detail["evidence_llr"] == 1.5
    res = d.step(V50, ahead(38.0, V50))
    tgt = res.targets.targets[0]
    assert tgt.verification is Verification.VERIFIED and "cannot_tell" not in tgt.gate_detail
    assert (res.command.decision, res.command.brake_level_pct) == (Decision.BRAKE, 50.0)


def test_a_cannot_tell_brake_is_held_and_kept_at_full_level():
    d = Drive(make_core(Script(None), decision=CANNOT_TELL))
    assert d.step(V50, ahead(22.0, V50)).command.brake_level_pct == 100.0
    # Slower now (the brake works), the stop needs less: the brake and its level stay.
    res = d.step(V50 * 0.8, ahead(20.5, V50 * 0.8))
    assert res.targets.targets[0].decision is Decision.WARNING
    assert (res.command.decision, res.command.brake_level_pct) == (Decision.BRAKE, 100.0)


def test_without_the_setting_a_cannot_tell_threat_follows_the_policy():
    d = Drive(make_core(Script(None), decision={"rule": "kinematic"}))
    res = d.step(V50, ahead(20.0, V50))               # the full stage: still WARNING
    assert res.command.decision is Decision.WARNING
    assert "camera unavailable, warn only" in res.targets.targets[0].reason
    radar_only = Drive(make_core(Script(None), decision={
        "rule": "kinematic", "unverifiable_policy": "radar_only"}))
    res = radar_only.step(V50, ahead(38.0, V50))
    assert (res.command.decision, res.command.brake_level_pct) == (Decision.BRAKE, 50.0)


def test_the_papers_rule_ignores_the_setting():
    core = make_core(Script(None), decision={
        **CANNOT_TELL, "rule": "paper", "unverifiable_policy": "ignore"})
    from tests.fusion.helpers import run, track
    t = run(core, track(x=10.0, vx=-8.0)).targets.targets[0]
    assert t.decision is Decision.NONE and "camera unavailable, ignored" in t.reason


def test_shipped_configs_the_default_brakes_cannot_tell_threats_at_full_only_the_paper_not():
    default = load_config(DEPLOY / "fusion.toml", FusionConfig).fusion
    assert default.decision.kinematic.cannot_tell_full_only
    assert default.decision.kinematic.cannot_tell_decel_mps2 == 5.5
    assert default.verifier.name == "recall_first"
    assert default.verifier.params["missing"] == "unverifiable"
    paper = load_config(DEPLOY / "fusion-paper.toml", FusionConfig).fusion
    assert paper.decision.rule.value == "paper" and paper.verifier.name == "edge_density"
    assert paper.decision.kinematic == KinematicSettings()
    assert not paper.decision.kinematic.cannot_tell_full_only


def test_cannot_tell_decel_below_the_full_stage_is_refused():
    with pytest.raises(ConfigError):
        settings(decision={"kinematic": {"cannot_tell_decel_mps2": 4.0}})


def cyclist_outside_the_image(d: Drive, v: float) -> list:
    """A cyclist 4 m ahead and 6 m to the right (56 deg: the radar's view, not the
    camera's), crossing left at 4 m/s: in the path when the ego arrives, TTC 1.4 s."""
    return [d.step(v, track(tid=4, x=4.0 - v * 0.075 * i, y=-6.0 + 4.0 * 0.075 * i,
                            vx=-v, vy=4.0))
            for i in range(3)]


def test_a_threat_outside_the_camera_s_view_brakes_at_the_full_stage_with_the_setting():
    v = 10 / 3.6
    on = Drive(make_core(FixedVerifier(verdict=False), decision={
        "rule": "kinematic", "kinematic": {"not_visible_full_only": True}}))
    res = cyclist_outside_the_image(on, v)[-1]
    tgt = res.targets.targets[0]
    assert tgt.verification is Verification.NOT_VISIBLE and tgt.path_predicted
    assert tgt.ttc_s is not None and tgt.ttc_s < 1.6
    assert (res.command.decision, res.command.brake_level_pct) == (Decision.BRAKE, 100.0)
    assert "outside the camera's view, full stage" in tgt.reason
    # without it, the unverifiable policy (warn): a WARNING at the full stage
    off = Drive(make_core(FixedVerifier(verdict=False), decision={"rule": "kinematic"}))
    res = cyclist_outside_the_image(off, v)[-1]
    assert res.command.decision is Decision.WARNING
    assert "camera not visible, warn only" in res.targets.targets[0].reason


def test_outside_the_camera_s_view_before_the_full_stage_is_a_warning():
    v = 30 / 3.6
    d = Drive(make_core(FixedVerifier(verdict=False), decision={
        "rule": "kinematic", "kinematic": {"not_visible_full_only": True}}))
    # 20 m ahead, 25 m to the side, crossing at 10 m/s: TTC 2.4 s, a warning stage
    res = d.step(v, track(tid=5, x=20.0, y=-25.0, vx=-v, vy=10.0))
    res = d.step(v, track(tid=5, x=20.0 - v * 0.075, y=-25.0 + 0.75, vx=-v, vy=10.0))
    tgt = res.targets.targets[0]
    assert tgt.verification is Verification.NOT_VISIBLE and tgt.path_predicted
    assert res.command.decision is Decision.WARNING
    assert "outside the camera's view, warning until the full stage" in tgt.reason
