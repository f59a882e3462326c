"""The fusion core: one radar cycle and the decoded frames in, VerifiedTargets and
exactly one BrakeCommand out. Pure: no Zenoh, no clocks (the shell passes the time), no
threads; its state is the brake hold, the sequence number and each track's recent
sideways motion (for path prediction).

Per confirmed track: kinematics and the radar's threat (decision.py); per camera, the
frame nearest the cycle within the skew bound (frames.py), the track predicted to that
frame's time and its column projected to a ROI (roi.py); the verifier (verifiers.py) in
the cameras that see it, combined (cameras.py); the decision. The command is the most
severe decision (ties: the smallest TTC_eff), or a heartbeat.
"""

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from common.config.fusion import FusionSettings, GateScope
from common.messages import (
    BrakeCommand,
    Decision,
    Header,
    RadarTrack,
    RadarTracks,
    Verification,
    VerifiedTarget,
    VerifiedTargets,
    VerifierStatus,
)
from services.fusion.cameras import Camera, CameraView, camera_views, check_track
from services.fusion.decision import (
    BrakeHold,
    DecisionRule,
    Kinematics,
    LateralMotion,
    decide,
    severity,
)
from services.fusion.frames import FrameFeed
from services.fusion.roi import ColumnProjector
from services.fusion.verifiers import Verifier

_NO_ROI: tuple[int, ...] = ()

CommandSink = Callable[[BrakeCommand], None]


@dataclass(frozen=True, slots=True)
class CycleResult:
    targets: VerifiedTargets
    command: BrakeCommand


class FusionCore:
    """`projectors`: one ColumnProjector (the one camera of the settings), or one per
    camera by name, in the order of `settings.camera_inputs`."""

    def __init__(self, settings: FusionSettings,
                 projectors: ColumnProjector | Mapping[str, ColumnProjector],
                 verifier: Verifier) -> None:
        self.s = settings
        names = [c.name for c in settings.camera_inputs]
        if isinstance(projectors, ColumnProjector):
            if len(names) != 1:
                raise ValueError(f"one projector for {len(names)} cameras")
            projectors = {names[0]: projectors}
        if sorted(projectors) != sorted(names):
            raise ValueError(f"projectors for {sorted(projectors)}, cameras {names}")
        self.cameras = tuple(Camera(n, projectors[n]) for n in names)
        self.projector = self.cameras[0].projector
        self.camera_names = ",".join(names)
        self.verifier = verifier
        self.verifier_params = verifier.params()
        self.source = f"fusion/{settings.instance}"
        self.hold = BrakeHold(round(settings.decision.hold_s * 1e9))
        self.rule = DecisionRule(settings.decision)
        p = settings.decision.corridor.prediction
        # Per-track memory of sideways motion, for path prediction (None when it is off).
        self.lateral = (LateralMotion(p.min_lateral_speed_mps, p.confirm_cycles)
                        if self.rule.predict else None)
        self._moving: set[int] = set()     # this cycle's tracks moving sideways
        self._seq = 0
        self.invalid_tracks = 0    # confirmed tracks with non-finite numbers, since start
        self._max_skew_ns = round(settings.frames.max_skew_s * 1e9)
        self._radar_max_age_ns = round(settings.decision.radar_max_age_s * 1e9)

    def process(self, tracks: RadarTracks, feeds: FrameFeed | Sequence[FrameFeed],
                now_wall_ns: int, now_mono_ns: int,
                on_command: CommandSink | None = None) -> CycleResult:
        """Decide one radar cycle. `feeds`: each camera's frames, in camera order (one
        FrameFeed for a single camera). `now_wall_ns` judges the radar's age;
        `now_mono_ns` stamps the messages' pub_mono_ns (the shell refreshes it at publish).

        `on_command` receives the cycle's BrakeCommand as soon as it is decided, before
        the gate has run on tracks that cannot change it: threats are checked most urgent
        first, and once one of them reaches the most its radar threat allows, nothing
        after it can be more severe. The targets are completed afterwards.
        Raises ValueError when the number of feeds is not the number of cameras.
        """
        s = self.s
        feeds = (feeds,) if isinstance(feeds, FrameFeed) else tuple(feeds)
        if len(feeds) != len(self.cameras):
            raise ValueError(f"{len(feeds)} frame feeds for {len(self.cameras)} cameras")
        confirmed: list[RadarTrack] = []
        invalid: list[RadarTrack] = []
        for t in tracks.tracks:
            if t.confirmed:
                (confirmed if _finite(t) else invalid).append(t)
        self.invalid_tracks += len(invalid)
        self._moving = self.lateral.update(confirmed) if self.lateral is not None else set()
        age_ns = now_wall_ns - tracks.header.stamp_ns
        # A stamp from the future beyond the bound means unsynchronised clocks: the age
        # is unknown, so the cycle is treated as stale.
        radar_stale = abs(age_ns) > self._radar_max_age_ns
        views: list[CameraView] = []
        reason_unavailable = ""
        if radar_stale:
            status = VerifierStatus.STALE_RADAR
        else:
            views = camera_views(self.cameras, feeds, confirmed, tracks.header.stamp_ns,
                                 self._max_skew_ns, s.frames.align)
            if any(v.frame is not None for v in views):
                status = VerifierStatus.OK
            else:
                status = VerifierStatus.UNAVAILABLE
                reason_unavailable = _reasons(views)
        cycle = _Cycle(tracks, confirmed, status, reason_unavailable, age_ns, now_wall_ns,
                       now_mono_ns, on_command)
        if radar_stale:
            targets = [self._stale_target(t, age_ns) for t in confirmed]
            self._send(cycle, targets)
        else:
            targets = self._verify_all(cycle, views)
        assert cycle.command is not None
        targets += [_invalid_target(t) for t in invalid]
        header = Header(seq=cycle.command.header.seq, source=self.source,
                        stamp_ns=tracks.header.stamp_ns, pub_mono_ns=now_mono_ns)
        verified = VerifiedTargets(
            header=header, instance=s.instance, radar_sensor=tracks.sensor,
            radar_seq=tracks.header.seq, verifier=self.verifier.name,
            verifier_params=self.verifier_params, verifier_status=status,
            targets=tuple(targets), processing_ns=0, camera=self.camera_names,
            unavailable_reason=reason_unavailable, radar_age_ms=age_ns / 1e6,
            frames_received=sum(f.received for f in feeds),
            frames_undecodable=sum(f.undecodable for f in feeds),
            frames_dropped=sum(f.dropped for f in feeds),
            frames_skipped=sum(f.skipped for f in feeds),
            cameras_unavailable={v.name: v.reason for v in views if v.frame is None})
        return CycleResult(verified, cycle.command)

    def _kinematics(self, t: RadarTrack) -> Kinematics:
        return self.rule.kinematics(t, t.track_id in self._moving)

    def _stale_target(self, t: RadarTrack, age_ns: int) -> VerifiedTarget:
        k = self._kinematics(t)
        reason = (f"radar stale (age {age_ns / 1e6:.0f} ms, max "
                  f"{self._radar_max_age_ns / 1e6:.0f} ms)")
        return VerifiedTarget(
            t.track_id, t.x_m, t.y_m, t.range_m, t.range_rate_mps, k.in_path,
            Verification.NOT_CHECKED, _NO_ROI, None, k.ttc_s, k.ttc_eff_s, Decision.NONE,
            reason, None, None, path_predicted=k.window is not None)

    def _verify_all(self, cycle: "_Cycle", views: list[CameraView]) -> list[VerifiedTarget]:
        rule = self.rule
        confirmed = cycle.confirmed
        radar_stamp_ns = cycle.tracks.header.stamp_ns
        kins = [self._kinematics(t) for t in confirmed]
        threats = [rule.threat(k) for k in kins]
        gate_all = self.s.gate_scope is GateScope.ALL
        verify = self.verifier.verify
        # Where a track no camera sees is reported: the first camera with a frame.
        fallback = next((v for v in views if v.frame is not None), views[0])
        out: list[VerifiedTarget | None] = [None] * len(confirmed)

        def evaluate(i: int) -> VerifiedTarget:
            t, k = confirmed[i], kins[i]
            threat, threat_reason = threats[i]
            check = check_track(i, views, threat is not Decision.NONE or gate_all, verify)
            verification = check.verification
            density = check.result.density if check.result is not None else None
            if verification is Verification.UNAVAILABLE and threat is not Decision.NONE:
                threat_reason = f"{threat_reason}; {_reasons(views, i)}"
            decision, reason = decide(threat, threat_reason, verification, rule.policy)
            if verification is Verification.REJECTED:
                reason = f"{reason}; density {density:.4f}"
            view = check.view or fallback
            frame = view.frame
            x, y = view.xy[i]
            tgt = VerifiedTarget(
                t.track_id, x, y, t.range_m, t.range_rate_mps, k.in_path, verification,
                _NO_ROI if check.roi is None or verification is Verification.UNAVAILABLE
                else tuple(check.roi), density, k.ttc_s, k.ttc_eff_s, decision, reason,
                frame.seq if frame is not None else None,
                (radar_stamp_ns - frame.stamp_ns) / 1e6 if frame is not None else None,
                check.result.detail if check.result is not None else {},
                path_predicted=k.window is not None,
                camera=check.view.name if check.view is not None else "",
                cameras=check.per_camera)
            out[i] = tgt
            return tgt

        # Threats, most severe first, then most urgent: once the best decision so far is
        # one the next threat cannot beat, the command is known.
        inf = float("inf")
        urgent = sorted((i for i in range(len(confirmed)) if threats[i][0] is not Decision.NONE),
                        key=lambda i: (-severity(threats[i][0]), kins[i].ttc_eff_s or inf))
        best: VerifiedTarget | None = None
        for i in urgent:
            if best is not None and not _could_beat(threats[i][0], kins[i].ttc_eff_s, best):
                break
            tgt = evaluate(i)
            if tgt.decision is not Decision.NONE and (best is None or _more_severe(tgt, best)):
                best = tgt
        self._send(cycle, [best] if best is not None else [], n_targets=len(confirmed))
        for i in range(len(confirmed)):
            if out[i] is None:
                evaluate(i)
        return [t for t in out if t is not None]

    def _send(self, cycle: "_Cycle", candidates: list[VerifiedTarget],
              n_targets: int | None = None) -> None:
        cycle.command = self._command(
            cycle.tracks, candidates, cycle.status, cycle.reason_unavailable, cycle.age_ns,
            cycle.now_wall_ns, cycle.now_mono_ns,
            n_targets=len(candidates) if n_targets is None else n_targets,
            confirmed=cycle.confirmed)
        if cycle.on_command is not None:
            cycle.on_command(cycle.command)

    def failed_cycle(self, tracks: RadarTracks, error: str, now_wall_ns: int,
                     now_mono_ns: int) -> CycleResult:
        """The cycle's command when processing raised: still exactly one command (NONE, or
        the held BRAKE), the verifier unavailable, the error as the reason."""
        age_ns = now_wall_ns - tracks.header.stamp_ns
        reason = f"fusion error: {error}"
        command = self._command(tracks, [], VerifierStatus.UNAVAILABLE, reason, age_ns,
                                now_wall_ns, now_mono_ns, summary=reason)
        header = Header(seq=command.header.seq, source=self.source,
                        stamp_ns=tracks.header.stamp_ns, pub_mono_ns=now_mono_ns)
        targets = VerifiedTargets(
            header=header, instance=self.s.instance, radar_sensor=tracks.sensor,
            radar_seq=tracks.header.seq, verifier=self.verifier.name,
            verifier_params=self.verifier_params, verifier_status=VerifierStatus.UNAVAILABLE,
            targets=(), processing_ns=0, camera=self.camera_names,
            unavailable_reason=reason, radar_age_ms=age_ns / 1e6)
        return CycleResult(targets, command)

    def _command(self, tracks: RadarTracks, targets: list[VerifiedTarget],
                 status: VerifierStatus, reason_unavailable: str, age_ns: int,
                 now_wall_ns: int, now_mono_ns: int, summary: str = "",
                 n_targets: int = 0, confirmed: list[RadarTrack] | None = None
                 ) -> BrakeCommand:
        """The command from the most severe of `targets` (ties: smallest TTC_eff), and the
        hold. `n_targets` counts every confirmed track, `confirmed` gives a held track's
        current range and TTC."""
        ds = self.s.decision
        worst: VerifiedTarget | None = None
        for tgt in targets:
            if worst is None or _more_severe(tgt, worst):
                worst = tgt
        decision = worst.decision if worst is not None else Decision.NONE
        n_targets = max(n_targets, len(targets))
        if summary:
            reason = summary
        elif n_targets == 0:
            reason = "no confirmed tracks"
        elif worst is None or decision is Decision.NONE:
            reason = f"no threat among {n_targets} confirmed tracks"
        else:
            reason = f"track {worst.track_id}: {worst.reason}"
        if status is VerifierStatus.STALE_RADAR:
            reason = f"radar stale (age {age_ns / 1e6:.0f} ms): {reason}"
        elif status is VerifierStatus.UNAVAILABLE and decision is Decision.NONE and not summary:
            reason = f"verifier unavailable ({reason_unavailable}): {reason}"
        track_id = worst.track_id if worst is not None and decision is not Decision.NONE else -1
        range_m = worst.range_m if track_id >= 0 and worst is not None else None
        ttc_s = worst.ttc_s if track_id >= 0 and worst is not None else None
        held = self.hold.update(decision, track_id, now_wall_ns)
        if held:
            track_id = self.hold.track_id
            left_ms = self.hold.remaining_ns(now_wall_ns) / 1e6
            reason = f"BRAKE held {left_ms:.0f} ms more; this cycle: {decision.value}, {reason}"
            decision = Decision.BRAKE
            # The held track as the radar sees it now, if it is still there.
            now = next((t for t in confirmed or () if t.track_id == track_id), None)
            range_m = now.range_m if now is not None else None
            ttc_s = self._kinematics(now).ttc_s if now is not None else None
        seq = self._seq
        self._seq += 1
        return BrakeCommand(
            header=Header(seq=seq, source=self.source, stamp_ns=tracks.header.stamp_ns,
                          pub_mono_ns=now_mono_ns),
            instance=self.s.instance, decision=decision,
            brake_level_pct=ds.brake_level_pct if decision is Decision.BRAKE else 0.0,
            verifier_status=status, held=held, track_id=track_id, range_m=range_m,
            ttc_s=ttc_s, reason=reason, radar_seq=tracks.header.seq,
            radar_last_frame_mono_ns=tracks.last_frame_mono_ns)


def _reasons(views: list[CameraView], track: int | None = None) -> str:
    """Why the cameras (that would see `track`, or all) have no usable frame; one camera:
    its reason alone, as before there were several."""
    missing = [v for v in views if v.frame is None
               and (track is None or v.rois[track] is not None)]
    if len(views) == 1:
        return missing[0].reason if missing else ""
    return "; ".join(f"{v.name}: {v.reason}" for v in missing)


def _finite(t: RadarTrack) -> bool:
    # One sum instead of six checks (per track, on the critical path): a NaN or an
    # infinity in any term makes it non-finite (inf - inf is NaN).
    return math.isfinite(t.x_m + t.y_m + t.vx_mps + t.vy_mps + t.range_m + t.range_rate_mps)


def _invalid_target(t: RadarTrack) -> VerifiedTarget:
    """A confirmed track with NaN or infinite numbers: reported, never decided on."""
    return VerifiedTarget(t.track_id, t.x_m, t.y_m, t.range_m, t.range_rate_mps, False,
                          Verification.NOT_CHECKED, _NO_ROI, None, None, None, Decision.NONE,
                          "invalid track: non-finite position, velocity or range", None, None)


def _more_severe(a: VerifiedTarget, b: VerifiedTarget) -> bool:
    sa, sb = severity(a.decision), severity(b.decision)
    if sa != sb:
        return sa > sb
    inf = float("inf")
    ta = a.ttc_eff_s if a.ttc_eff_s is not None else inf
    tb = b.ttc_eff_s if b.ttc_eff_s is not None else inf
    return ta < tb


def _could_beat(threat: Decision, ttc_eff_s: float | None, best: VerifiedTarget) -> bool:
    """Could a track whose radar threat is `threat` end more severe than `best`? Its
    decision is at most its threat."""
    s, sb = severity(threat), severity(best.decision)
    if s != sb:
        return s > sb
    inf = float("inf")
    tb = best.ttc_eff_s if best.ttc_eff_s is not None else inf
    return (ttc_eff_s if ttc_eff_s is not None else inf) < tb


class _Cycle:
    """One cycle's context while it is processed."""

    def __init__(self, tracks: RadarTracks, confirmed: list[RadarTrack], status: VerifierStatus,
                 reason_unavailable: str, age_ns: int, now_wall_ns: int, now_mono_ns: int,
                 on_command: "CommandSink | None") -> None:
        self.tracks = tracks
        self.confirmed = confirmed
        self.status = status
        self.reason_unavailable = reason_unavailable
        self.age_ns = age_ns
        self.now_wall_ns = now_wall_ns
        self.now_mono_ns = now_mono_ns
        self.on_command = on_command
        self.command: BrakeCommand | None = None
