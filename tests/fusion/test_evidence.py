"""Evidence over time: a per-frame llr summed per track between a floor and a ceiling,
so that one bad frame neither brakes nor vetoes; published per cycle in gate_detail."""

import pytest

from aeb_radar_camera.common.config.loader import ConfigError
from aeb_radar_camera.common.messages import Decision, Verification
from aeb_radar_camera.services.fusion.verifiers import GateResult, Observation, ParamValue
from tests.fusion.helpers import MS, T0, feed, make_core, run, settings, track

CYCLE_NS = 74 * MS


class Scripted:
    """Answers the llr of a script, one per call (a recall_first-like verifier)."""

    name = "scripted"
    needs_depth = False

    def __init__(self, *llrs: float, unverifiable: bool = False) -> None:
        self.llrs = list(llrs)
        self.unverifiable = unverifiable

    def params(self) -> dict[str, ParamValue]:
        return {}

    def verify(self, obs: Observation) -> GateResult:
        llr = self.llrs.pop(0)
        return GateResult(llr, llr >= 0, {"llr": llr}, "llr", self.unverifiable)


def drive(core, n: int, tid: int = 1, start: int = 0):
    """n cycles of a track closing at 8 m/s 2.5 s away (a BRAKE if confirmed)."""
    out = []
    for i in range(start, start + n):
        result = run(core, track(tid, x=20.0 - 0.6 * (i - start), vx=-8.0),
                     stamp_ns=T0 + i * CYCLE_NS,
                     seq=i)
        out.append(result.targets.targets[0])
    return out


def test_a_real_obstacle_keeps_its_brake_through_one_bad_frame():
    core = make_core(Scripted(1.5, 1.5, 1.5, -1.0, 1.5), decision={"hold_s": 0.0})
    got = drive(core, 5)
    assert [t.gate_detail["evidence_llr"] for t in got] == [1.5, 3.0, 4.0, 3.0, 4.0]
    assert all(t.verification is Verification.VERIFIED for t in got)
    assert got[3].gate_detail["llr"] == -1.0 and got[3].decision is Decision.BRAKE


def test_a_false_target_stays_vetoed_through_one_good_frame():
    core = make_core(Scripted(-1.0, -1.0, -1.0, -1.0, -1.0, 1.5, -1.0))
    got = drive(core, 7)
    assert [t.gate_detail["evidence_llr"] for t in got] == [-1.0, -2.0, -3.0, -4.0, -4.0,
                                                             -2.5, -3.5]
    assert all(t.verification is Verification.REJECTED for t in got)
    assert all(t.decision is Decision.NONE for t in got)
    assert "evidence -2.50" in got[5].reason


def test_evidence_is_per_track_and_forgotten_after_forget_s():
    core = make_core(Scripted(-1.0, -1.0, 1.5), evidence={"forget_s": 0.5})
    a = drive(core, 2, tid=1)
    assert a[-1].gate_detail["evidence_llr"] == -2.0
    # The same id 2 s later is a new track as far as evidence goes.
    (b,) = drive(core, 1, tid=1, start=30)
    assert b.gate_detail["evidence_llr"] == 1.5 and b.verification is Verification.VERIFIED


def test_unverifiable_frames_follow_the_policy_unless_evidence_vetoes():
    core = make_core(Scripted(0.0, 0.0, unverifiable=True))
    got = drive(core, 1)
    assert got[0].verification is Verification.UNAVAILABLE
    assert got[0].decision is Decision.WARNING          # the default policy: warn
    assert "camera cannot tell" in got[0].reason


def test_a_verifier_without_llr_decides_per_frame_and_evidence_can_be_off():
    from tests.fusion.helpers import FixedVerifier
    core = make_core(FixedVerifier(verdict=True))
    (t,) = drive(core, 1)
    assert "evidence_llr" not in t.gate_detail and t.verification is Verification.VERIFIED
    off = make_core(Scripted(-1.0), evidence={"enabled": False})
    (t,) = drive(off, 1)
    assert "evidence_llr" not in t.gate_detail and t.verification is Verification.REJECTED


def test_evidence_settings_are_validated():
    assert settings().evidence.floor == -4.0 and settings().evidence.ceiling == 4.0
    with pytest.raises(ConfigError):
        settings(evidence={"floor": -1.0, "veto_at": -2.0})
    with pytest.raises(ConfigError):
        settings(evidence={"veto_at": 0.5})


def test_a_track_out_of_view_keeps_its_evidence_and_a_new_id_near_it_takes_it_over():
    from aeb_radar_camera.services.fusion.evidence import TrackEvidence
    ev = TrackEvidence(settings().evidence)
    for i in range(3):
        ev.add(4, 1.5, T0 + i * CYCLE_NS, (5.0, -4.0))
    now = T0 + 10 * CYCLE_NS                      # 0.5 s after the last frame
    assert ev.carried(4, (4.6, -3.8), now) == 4.0
    # The radar restarts the cyclist as track 21 nearby: it takes track 4's sum ...
    assert ev.carried(21, (3.0, -3.2), now) == 4.0
    # ... but not a track far away, nor one long after.
    assert ev.carried(22, (12.0, 1.0), now) is None
    assert ev.carried(23, (3.0, -3.2), T0 + 40 * CYCLE_NS) is None



def test_a_vetoed_track_no_frame_shows_is_decided_on_its_carried_evidence():
    """No frame this cycle: the veto the evidence reached stands, said in the reason
    (the cycle once failed formatting the absent frame's score)."""
    v = Scripted(-1.0, -1.0, -1.0, -1.0)
    v.gives_llr = True                             # type: ignore[attr-defined]
    core = make_core(v)
    got = drive(core, 4)
    assert got[-1].verification is Verification.REJECTED
    t = run(core, track(1, x=20.0 - 0.6 * 4, vx=-8.0), frames=feed(),
            stamp_ns=T0 + 4 * CYCLE_NS, seq=4).targets.targets[0]
    assert t.verification is Verification.REJECTED and t.decision is Decision.NONE
    assert t.gate_detail["evidence_carried"] == 1.0
    assert "evidence -4.00 carried" in t.reason, t.reason


def test_closing_tracks_that_are_not_threats_yet_are_checked_for_their_evidence():
    v = Scripted(1.5, 1.5, 1.5)
    v.gives_llr = True                             # type: ignore[attr-defined]
    core = make_core(v)
    # 24 m ahead closing at 3 m/s: TTC 8 s, no threat; its evidence is gathered anyway.
    t = run(core, track(1, x=24.0, vx=-3.0)).targets.targets[0]
    assert t.decision is Decision.NONE and t.gate_detail["evidence_llr"] == 1.5
    # Without `gives_llr` a non-threat is not gated (the default gate scope).
    plain = make_core(Scripted(1.5))
    t = run(plain, track(1, x=24.0, vx=-3.0)).targets.targets[0]
    assert t.verification is Verification.NOT_CHECKED
