"""Tentative tracks (`[fusion.evidence] tentative_hits`): a track the radar's tracker has
not confirmed yet is decided on once the camera's evidence confirms it (a surface at its
range), never on the radar alone, and not at all without the setting."""

import msgspec
import pytest

from aeb_radar_camera.common.config.loader import ConfigError
from aeb_radar_camera.common.messages import Decision, RadarTrack, Verification
from aeb_radar_camera.services.fusion.verifiers import GateResult, Observation
from tests.fusion.helpers import make_core, settings
from tests.fusion.test_cannot_tell import CANNOT_TELL, V50, Script
from tests.fusion.test_decision_kinematic import Drive, ahead

TENTATIVE = {"tentative_hits": 2}


def tentative(x: float, hits: int = 2, tid: int = 7) -> RadarTrack:
    """A stationary object x m ahead at 50 km/h that the tracker has seen `hits` times."""
    return msgspec.structs.replace(ahead(x, V50, tid=tid), confirmed=False, hits=hits)


def drive(verifier: object, **evidence: object) -> Drive:
    return Drive(make_core(verifier, decision=CANNOT_TELL, evidence=evidence))


def test_a_tentative_threat_the_camera_confirms_is_braked_for_a_cycle_early():
    res = drive(Script(1.5), **TENTATIVE).step(V50, tentative(22.0))
    tgt = res.targets.targets[0]
    assert (res.command.decision, res.command.brake_level_pct) == (Decision.BRAKE, 100.0)
    assert tgt.track_id == 7 and tgt.verification is Verification.VERIFIED
    assert "tentative track (2 hits) the camera confirms" in tgt.reason
    assert res.command.track_id == 7


@pytest.mark.parametrize("llr", [None, 0.0, -1.0])
def test_without_a_confirmation_a_tentative_track_neither_warns_nor_brakes(llr):
    # Depth too sparse (a false target the camera cannot tell is never braked for on a
    # tentative track), ambiguous, or seeing through it.
    res = drive(Script(llr), **TENTATIVE).step(V50, tentative(22.0))
    assert res.command.decision is Decision.NONE
    (tgt,) = res.targets.targets
    assert tgt.decision is Decision.NONE
    assert ("camera rejected" if llr == -1.0 else
            "tentative track (2 hits) the camera has not confirmed") in tgt.reason


def test_too_few_hits_or_the_setting_off_and_the_track_is_not_decided_on():
    one_hit = drive(Script(1.5), **TENTATIVE).step(V50, tentative(22.0, hits=1))
    off = drive(Script(1.5)).step(V50, tentative(22.0))
    for res in (one_hit, off):
        assert res.command.decision is Decision.NONE and res.targets.targets == ()


class Counting(Script):
    def __init__(self) -> None:
        super().__init__(1.5)
        self.calls = 0

    def verify(self, obs: Observation) -> GateResult:
        self.calls += 1
        return super().verify(obs)


def test_a_tentative_track_that_is_no_threat_is_neither_checked_nor_reported():
    verifier = Counting()
    d = drive(verifier, **TENTATIVE)
    res = d.step(V50, tentative(90.0))
    assert res.targets.targets == () and verifier.calls == 0
    assert d.step(V50, tentative(22.0)).command.decision is Decision.BRAKE
    assert verifier.calls == 1


def test_its_evidence_carries_over_once_the_radar_confirms_it():
    d = drive(Script(1.5, -1.0), **TENTATIVE)
    d.step(V50, tentative(40.0))
    confirmed = msgspec.structs.replace(tentative(38.9, hits=3), confirmed=True)
    tgt = d.step(V50, confirmed).targets.targets[0]
    assert tgt.gate_detail["evidence_llr"] == 0.5          # 1.5 then -1.0
    assert tgt.verification is Verification.VERIFIED


def test_the_setting_is_checked():
    assert settings(evidence=TENTATIVE).evidence.tentative_hits == 2
    assert settings().evidence.tentative_hits == 0
    with pytest.raises(ConfigError, match="tentative_hits"):
        settings(evidence={"tentative_hits": -1})
