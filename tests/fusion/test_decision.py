"""Every branch of the decision (radar threat, stale radar, camera verdict, unverifiable
policy, hold, gate scope), on the pure core."""

import pytest

from aeb_radar_camera.common.messages import Decision, Verification, VerifierStatus
from aeb_radar_camera.services.fusion.frames import FrameDecoder
from aeb_radar_camera.services.fusion.verifiers import GateResult
from tests.fusion.helpers import (
    MS,
    T0,
    FixedVerifier,
    cycle,
    feed,
    frame,
    make_core,
    most_severe,
    run,
    track,
)


def only(result):
    assert len(result.targets.targets) == 1
    return result.targets.targets[0]


def test_verified_closing_track_in_range_brakes_with_the_configured_level():
    core = make_core(decision={"brake_level_pct": 80.0})
    res = run(core, track(tid=4, x=10.0, vx=-5.0))          # TTC 2.0 s, TTC_eff 1.0 s
    tgt, cmd = only(res), res.command
    assert (tgt.ttc_s, tgt.ttc_eff_s) == pytest.approx((2.0, 1.0))
    assert tgt.verification is Verification.VERIFIED and tgt.decision is Decision.BRAKE
    assert cmd.decision is Decision.BRAKE and cmd.brake_level_pct == 80.0
    assert (cmd.track_id, cmd.range_m, cmd.ttc_s) == (4, 10.0, pytest.approx(2.0))
    assert cmd.held is False and cmd.verifier_status is VerifierStatus.OK
    assert "verified" in cmd.reason


@pytest.mark.parametrize(("range_m", "expected"), [
    (2.99, Decision.NONE), (3.0, Decision.BRAKE), (25.0, Decision.BRAKE), (25.01, Decision.NONE),
])
def test_range_bounds_3_and_25_m_are_inclusive(range_m, expected):
    # -10 m/s keeps TTC_eff below 2.5 s at 25 m (2.5 - 1.0 = 1.5 s).
    res = run(make_core(), track(x=range_m, vx=-10.0))
    assert res.command.decision is expected
    if expected is Decision.NONE:
        assert "outside [3, 25] m" in only(res).reason


@pytest.mark.parametrize(("range_m", "closing_mps", "expected"), [
    (7.0, 2.0001, Decision.BRAKE),     # TTC_eff just below 2.5 s
    (7.0, 2.0, Decision.WARNING),      # TTC 3.5 s, TTC_eff exactly 2.5 s: not below
    (9.99, 2.0, Decision.WARNING),     # TTC_eff 3.995 s < 4.0 s
    (10.0, 2.0, Decision.NONE),        # TTC_eff exactly 4.0 s: no warning
])
def test_ttc_eff_bounds_split_brake_warning_and_none(range_m, closing_mps, expected):
    res = run(make_core(), track(x=range_m, vx=-closing_mps))
    assert only(res).decision is expected
    assert res.command.decision is expected
    assert res.command.brake_level_pct == (100.0 if expected is Decision.BRAKE else 0.0)


@pytest.mark.parametrize("range_rate", [2.0, 0.0])
def test_receding_or_constant_range_never_brakes_and_has_no_ttc(range_rate):
    verifier = FixedVerifier()
    res = run(make_core(verifier), track(x=5.0, vx=range_rate, range_rate=range_rate))
    tgt = only(res)
    assert tgt.ttc_s is None and tgt.ttc_eff_s is None
    assert tgt.decision is Decision.NONE and "not closing" in tgt.reason
    # Outside the decision, the gate does not run by default (gate_scope = candidates).
    assert tgt.verification is Verification.NOT_CHECKED and verifier.calls == []
    assert res.command.decision is Decision.NONE and res.command.track_id == -1


@pytest.mark.parametrize(("y", "corridor", "expected"), [
    (1.2, {}, Decision.BRAKE),                              # 0.9 + 0.3: on the edge, in
    (1.21, {}, Decision.NONE),
    (-1.3, {}, Decision.NONE),
    (-1.3, {"enabled": False}, Decision.BRAKE),
    (1.6, {"center_y_m": 0.5}, Decision.BRAKE),             # radar 0.5 m right of centre
    (2.0, {"half_width_m": 1.5, "margin_m": 0.5}, Decision.BRAKE),
])
def test_in_path_corridor(y, corridor, expected):
    core = make_core(decision={"corridor": corridor})
    res = run(core, track(x=8.0, y=y, vx=-5.0, vy=0.0, range_rate=-5.0))
    tgt = only(res)
    assert tgt.decision is expected
    assert tgt.in_path is (expected is Decision.BRAKE)
    if expected is Decision.NONE:
        assert "out of corridor" in tgt.reason


def test_camera_rejection_means_no_brake_and_records_the_density():
    res = run(make_core(FixedVerifier(verdict=False, density=0.011)), track())
    tgt = only(res)
    assert tgt.verification is Verification.REJECTED and tgt.density == 0.011
    assert tgt.decision is Decision.NONE and res.command.decision is Decision.NONE
    assert "camera rejected" in tgt.reason and "0.0110" in tgt.reason


@pytest.mark.parametrize(("policy", "expected"), [
    ("warn", Decision.WARNING), ("ignore", Decision.NONE), ("radar_only", Decision.BRAKE),
])
def test_a_track_outside_the_image_is_not_visible_never_verified(policy, expected):
    verifier = FixedVerifier(verdict=True)
    core = make_core(verifier, decision={"unverifiable_policy": policy,
                                         "corridor": {"enabled": False}})
    # 12 m ahead, 9 m to the left: outside the 69 degree field of view.
    res = run(core, track(x=12.0, y=9.0, vx=-8.0, vy=0.0))
    tgt = only(res)
    assert tgt.verification is Verification.NOT_VISIBLE and tgt.roi_xywh == ()
    assert verifier.calls == []
    assert tgt.decision is expected and res.command.decision is expected
    assert res.command.verifier_status is VerifierStatus.OK


def test_stale_radar_never_brakes_and_skips_the_gate():
    verifier = FixedVerifier(verdict=True)
    core = make_core(verifier)
    res = run(core, track(x=6.0, vx=-10.0), now_ns=T0 + 161 * MS)   # bound 160 ms
    assert res.command.decision is Decision.NONE and res.command.brake_level_pct == 0.0
    assert res.command.verifier_status is VerifierStatus.STALE_RADAR
    assert res.targets.verifier_status is VerifierStatus.STALE_RADAR
    tgt = only(res)
    assert tgt.verification is Verification.NOT_CHECKED and verifier.calls == []
    assert "radar stale" in tgt.reason and "radar stale" in res.command.reason
    # Just inside the bound, the same cycle brakes.
    fresh = run(make_core(), track(x=6.0, vx=-10.0), now_ns=T0 + 159 * MS)
    assert fresh.command.decision is Decision.BRAKE


def test_a_radar_stamp_from_the_future_is_treated_as_stale():
    res = run(make_core(), track(x=6.0, vx=-10.0), now_ns=T0 - 500 * MS)
    assert res.command.verifier_status is VerifierStatus.STALE_RADAR
    assert res.command.decision is Decision.NONE


@pytest.mark.parametrize(("policy", "expected"), [
    ("warn", Decision.WARNING), ("ignore", Decision.NONE), ("radar_only", Decision.BRAKE),
])
def test_a_frame_too_far_from_the_radar_cycle_makes_the_verifier_unavailable(policy, expected):
    verifier = FixedVerifier(verdict=True)
    core = make_core(verifier, decision={"unverifiable_policy": policy})
    old = feed(frame(T0 - 150 * MS))                                # max skew 100 ms
    res = run(core, track(), frames=old)
    assert res.command.verifier_status is VerifierStatus.UNAVAILABLE
    assert res.targets.verifier_status is VerifierStatus.UNAVAILABLE
    assert "-150 ms from the radar cycle" in res.targets.unavailable_reason
    tgt = only(res)
    assert tgt.verification is Verification.UNAVAILABLE and verifier.calls == []
    assert tgt.decision is expected and res.command.decision is expected


def test_no_frame_at_all_is_unavailable_not_no_obstacle():
    res = run(make_core(), track(), frames=feed())
    assert res.command.verifier_status is VerifierStatus.UNAVAILABLE
    assert res.targets.unavailable_reason == "no camera frame received"
    assert res.command.decision is Decision.WARNING             # default policy: warn


def test_a_corrupt_newest_frame_makes_the_verifier_unavailable_with_the_reason(tmp_path):
    from tests.fusion.test_frames import compressed, decoder

    dec: FrameDecoder = decoder()
    good = compressed(stamp_ns=T0 - 300 * MS, seq=1)
    dec.decode_now(good, rx_mono_ns=1)
    corrupt = compressed(stamp_ns=T0, seq=2, truncate=True)
    dec.decode_now(corrupt, rx_mono_ns=2)
    snap = dec.snapshot()
    assert (snap.received, snap.undecodable, len(snap.frames)) == (0, 1, 1)
    res = run(make_core(), track(), frames=snap)
    assert res.command.verifier_status is VerifierStatus.UNAVAILABLE
    assert "newest frame unusable" in res.targets.unavailable_reason
    assert "undecodable JPEG" in res.targets.unavailable_reason
    assert res.targets.frames_undecodable == 1
    assert res.command.decision is Decision.WARNING
    # A good frame arriving afterwards, near the cycle, restores verification.
    dec.decode_now(compressed(stamp_ns=T0 + 10 * MS, seq=3), rx_mono_ns=3)
    res = run(make_core(), track(), frames=dec.snapshot())
    assert res.command.verifier_status is VerifierStatus.OK
    assert only(res).frame_seq == 3


def test_brake_is_held_for_the_minimum_time_then_released():
    core = make_core(decision={"hold_s": 0.5})
    t = T0
    first = run(core, track(tid=9, x=8.0, vx=-6.0), stamp_ns=t)
    assert first.command.decision is Decision.BRAKE and not first.command.held
    # The threat vanishes: the brake stays on, marked held, for the deciding track.
    nxt = run(core, stamp_ns=t + 75 * MS)
    assert nxt.command.decision is Decision.BRAKE and nxt.command.held
    assert nxt.command.track_id == 9 and nxt.command.brake_level_pct == 100.0
    assert "held" in nxt.command.reason
    # Still inside 0.5 s of the last BRAKE decision (decided at now = t + 5 ms).
    late = run(core, stamp_ns=t + 495 * MS, now_ns=t + 500 * MS)
    assert late.command.held
    done = run(core, stamp_ns=t + 500 * MS, now_ns=t + 506 * MS)
    assert done.command.decision is Decision.NONE and not done.command.held
    assert done.command.brake_level_pct == 0.0


def test_a_new_brake_decision_extends_the_hold():
    core = make_core(decision={"hold_s": 0.3})
    run(core, track(x=8.0, vx=-6.0), stamp_ns=T0)
    run(core, track(x=7.5, vx=-6.0), stamp_ns=T0 + 200 * MS)
    res = run(core, stamp_ns=T0 + 400 * MS)                # 0.2 s after the second BRAKE
    assert res.command.held and res.command.decision is Decision.BRAKE


def test_stale_radar_does_not_start_a_brake_but_does_not_cut_a_held_one():
    core = make_core(decision={"hold_s": 1.0})
    run(core, track(x=8.0, vx=-6.0), stamp_ns=T0)
    res = run(core, track(x=7.5, vx=-6.0), stamp_ns=T0 + 75 * MS, now_ns=T0 + 400 * MS)
    assert res.command.verifier_status is VerifierStatus.STALE_RADAR
    assert res.command.decision is Decision.BRAKE and res.command.held


def test_no_hold_when_hold_is_zero():
    core = make_core(decision={"hold_s": 0.0})
    assert run(core, track(x=8.0, vx=-6.0)).command.decision is Decision.BRAKE
    res = run(core, stamp_ns=T0 + 75 * MS)
    assert res.command.decision is Decision.NONE and not res.command.held


def test_heartbeat_every_cycle_with_sequence_and_latency_chain():
    core = make_core()
    cmds = []
    for i in range(4):
        tracks = (track(confirmed=False),) if i == 2 else ()
        res = core.process(cycle(*tracks, seq=100 + i, stamp_ns=T0 + i * 75 * MS,
                                 last_frame_mono_ns=5000 + i),
                           feed(frame(T0 + i * 75 * MS)), T0 + i * 75 * MS + MS, 7)
        cmds.append(res.command)
        assert res.targets.header.seq == res.command.header.seq
        assert res.targets.targets == ()        # unconfirmed tracks are not targets
    assert [c.header.seq for c in cmds] == [0, 1, 2, 3]
    assert [c.radar_seq for c in cmds] == [100, 101, 102, 103]
    assert [c.radar_last_frame_mono_ns for c in cmds] == [5000, 5001, 5002, 5003]
    assert all(c.decision is Decision.NONE and c.track_id == -1 for c in cmds)
    assert all(c.reason == "no confirmed tracks" for c in cmds)
    assert cmds[0].header.source == "fusion/primary" and cmds[0].instance == "primary"
    assert cmds[1].header.stamp_ns == T0 + 75 * MS


def test_the_command_is_the_most_severe_decision_then_the_smallest_ttc_eff():
    # gate_scope = all: every track is gated, so every target carries its own decision.
    res = run(make_core(gate_scope="all"), track(tid=1, x=9.0, vx=-2.5),  # WARNING (2.6 s)
              track(tid=2, x=10.0, vx=-5.0),                  # BRAKE (TTC_eff 1.0 s)
              track(tid=3, x=6.0, vx=-5.0),                   # BRAKE (TTC_eff 0.2 s)
              track(tid=4, x=20.0, vx=3.0))                   # receding
    assert [t.decision for t in res.targets.targets] == [
        Decision.WARNING, Decision.BRAKE, Decision.BRAKE, Decision.NONE]
    assert res.command.decision is Decision.BRAKE and res.command.track_id == 3


def test_gate_scope_all_runs_the_gate_on_every_visible_track():
    verifier = FixedVerifier(verdict=True)
    res = run(make_core(verifier, gate_scope="all"), track(x=20.0, vx=3.0))
    tgt = only(res)
    assert tgt.verification is Verification.VERIFIED and len(verifier.calls) == 1
    assert tgt.decision is Decision.NONE


def test_every_decision_records_the_verifier_name_and_parameters():
    res = run(make_core(FixedVerifier()), track())
    assert res.targets.verifier == "fixed"
    assert res.targets.verifier_params == {"verdict": True}
    real = run(make_core(None, verifier={"name": "edge_density", "params": {"tau": 0.03}}),
               track())
    assert real.targets.verifier == "edge_density"
    assert real.targets.verifier_params == {"low": 40.0, "high": 120.0, "tau": 0.03}


def test_a_failed_cycle_still_answers_once_and_keeps_a_held_brake():
    core = make_core(decision={"hold_s": 1.0})
    run(core, track(x=8.0, vx=-6.0))
    res = core.failed_cycle(cycle(seq=1, stamp_ns=T0 + 75 * MS), "boom", T0 + 80 * MS, 1)
    assert res.command.header.seq == 1
    assert res.command.decision is Decision.BRAKE and res.command.held
    assert "fusion error: boom" in res.command.reason
    assert res.command.verifier_status is VerifierStatus.UNAVAILABLE
    fresh = make_core().failed_cycle(cycle(), "boom", T0, 1)
    assert fresh.command.decision is Decision.NONE



def test_the_command_is_decided_before_the_threats_that_cannot_change_it_are_gated():
    verifier = FixedVerifier(verdict=True)
    core = make_core(verifier)
    tracks = (track(tid=1, x=12.0, vx=-5.0),       # BRAKE threat, TTC_eff 1.4 s
              track(tid=2, x=6.0, vx=-5.0),        # BRAKE threat, TTC_eff 0.2 s: first
              track(tid=3, x=20.0, vx=3.0))        # no threat
    decided = core.decide(cycle(*tracks), feed(frame()), T0 + 5 * MS, 1)
    assert len(verifier.calls) == 1                # the most urgent threat, verified
    assert decided.command.decision is Decision.BRAKE and decided.command.track_id == 2
    targets = core.report(decided)
    assert len(verifier.calls) == 2                # the other threat, for the report
    first, urgent, receding = targets.targets
    assert urgent.verification is Verification.VERIFIED
    assert first.verification is Verification.VERIFIED and first.decision is Decision.BRAKE
    assert receding.verification is Verification.NOT_CHECKED
    assert receding.reason.startswith("not closing")
    assert targets.header.seq == decided.command.header.seq


def test_a_rejected_urgent_track_lets_the_next_threat_decide():
    verdicts = iter([False, True])                 # first call (most urgent) rejects

    class Scripted(FixedVerifier):
        def verify(self, obs):
            self.calls.append(obs.roi)
            return GateResult(0.1, next(verdicts))

    verifier = Scripted()
    res = run(make_core(verifier), track(tid=1, x=12.0, vx=-5.0), track(tid=2, x=6.0, vx=-5.0))
    assert len(verifier.calls) == 2
    assert res.command.decision is Decision.BRAKE and res.command.track_id == 1
    assert res.targets.targets[1].verification is Verification.REJECTED


def test_a_threat_is_gated_for_the_command_only_while_it_can_beat_it():
    verifier = FixedVerifier(verdict=True)
    core = make_core(verifier, decision={"corridor": {"enabled": False}})
    hidden = track(tid=1, x=4.0, y=-9.0, vx=-12.0)   # BRAKE threat no camera sees
    brake = track(tid=2, x=12.0, vx=-5.0)            # BRAKE threat, TTC_eff 1.4 s
    warn = track(tid=3, x=18.0, vx=-5.0)             # WARNING threat, TTC_eff 2.6 s
    # The hidden track is a WARNING (policy warn), more urgent than the WARNING threat.
    decided = core.decide(cycle(hidden, warn), feed(frame()), T0 + 5 * MS, 1)
    assert decided.command.decision is Decision.WARNING and decided.command.track_id == 1
    assert verifier.calls == []
    targets = core.report(decided).targets
    assert targets[0].verification is Verification.NOT_VISIBLE
    assert targets[1].verification is Verification.VERIFIED and len(verifier.calls) == 1
    # A BRAKE threat can still beat that WARNING: it is gated, and decides.
    verifier.calls.clear()
    decided = core.decide(cycle(hidden, brake, warn, seq=1), feed(frame()), T0 + 5 * MS, 1)
    assert decided.command.decision is Decision.BRAKE and decided.command.track_id == 2
    assert len(verifier.calls) == 1


def test_the_command_does_not_depend_on_the_gate_scope():
    import random

    rng = random.Random(7)

    class ByRoi(FixedVerifier):
        """A verdict that depends on the ROI only, so both scopes see the same one."""

        def verify(self, obs):
            self.calls.append(obs.roi)
            return GateResult(0.1, hash(tuple(obs.roi)) % 2 == 0)

    for policy in ("warn", "ignore", "radar_only"):
        scoped = {scope: make_core(ByRoi(), gate_scope=scope,
                                   decision={"hold_s": 0.0, "unverifiable_policy": policy})
                  for scope in ("candidates", "all")}
        for n in range(80):
            tracks = [track(tid=i, x=rng.uniform(2.0, 27.0), y=rng.uniform(-1.5, 1.5),
                            vx=rng.uniform(-12.0, 3.0)) for i in range(rng.randint(0, 8))]
            frames = feed(frame()) if n % 5 else feed()
            res = {scope: core.process(cycle(*tracks, seq=n), frames, T0 + MS, 1)
                   for scope, core in scoped.items()}
            cmds = [(r.command.decision, r.command.track_id, r.command.reason)
                    for r in res.values()]
            assert cmds[0] == cmds[1]
            for r in res.values():
                assert (r.command.decision, r.command.track_id) == most_severe(
                    r.targets.targets)


def test_tracks_with_non_finite_numbers_are_reported_and_never_decided_on():
    import math

    core = make_core()
    bad = [track(tid=1, x=math.nan), track(tid=2, x=math.inf),
           track(tid=3, vx=math.nan, range_rate=-5.0), track(tid=4, range_rate=math.nan)]
    res = run(core, *bad, track(tid=5, x=8.0, vx=-6.0))
    assert res.command.decision is Decision.BRAKE and res.command.track_id == 5
    reported = {t.track_id: t for t in res.targets.targets}
    assert set(reported) == {1, 2, 3, 4, 5}
    for tid in (1, 2, 3, 4):
        assert reported[tid].decision is Decision.NONE
        assert reported[tid].reason.startswith("invalid track")
    assert core.invalid_tracks == 4
