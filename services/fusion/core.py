"""The fusion core: one radar cycle and the decoded frames in, exactly one BrakeCommand
and the cycle's VerifiedTargets out. Pure: no Zenoh, no clocks (the shell passes the
time), no threads; its state is the brake hold, the sequence number and each track's
recent sideways motion (for path prediction).

Per confirmed track: kinematics and the radar's threat (decision.py); per camera, the
frame nearest the cycle within the skew bound (frames.py), the track predicted to that
frame's time and its column projected to a ROI (roi.py); the verifier (verifiers/) in
the cameras that see it, combined (cameras.py); the decision. The command is the most
severe decision (ties: the smallest TTC_eff), or a heartbeat.

A cycle is two steps. `decide` settles the command: threats are checked most severe
first, then most urgent; a track's decision is at most its radar threat, so once the
command so far ranks at least as high as the next threat, nothing after it can change the
command. `report` then describes every confirmed track: the remaining threats are gated
too, and with `gate_scope = "all"` every visible track. `process` is both.
"""

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import msgspec

from aeb_radar_camera.common.config.fusion import FusionSettings, GateScope, RuleName
from aeb_radar_camera.common.messages import (
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
from aeb_radar_camera.common.messages.vehicle import DriverInputs, EgoMotion
from aeb_radar_camera.common.vehicle_state import VehicleSample, VehicleState
from aeb_radar_camera.services.fusion.cameras import Camera, CameraView, camera_views, check_track
from aeb_radar_camera.services.fusion.decision import (
    BrakeHold,
    CommandStage,
    DecisionRule,
    KinematicRule,
    Kinematics,
    LateralMotion,
    decide,
    severity,
)
from aeb_radar_camera.services.fusion.evidence import (
    BESIDE_PATH,
    CANNOT_TELL_KEY,
    EVIDENCE_CARRIED_KEY,
    EVIDENCE_KEY,
    IN_VIEW,
    INTO_PATH,
    LLR_KEY,
    ROAD_EDGE,
    TrackEvidence,
)
from aeb_radar_camera.services.fusion.frames import (
    EXPECTED_CHANGE_SPAN,
    FROZEN_REASON,
    FrameFeed,
    expected_change_px,
    frozen,
    unchanged_for_ns,
)
from aeb_radar_camera.services.fusion.roi import ColumnProjector
from aeb_radar_camera.services.fusion.verifiers import Verifier
from aeb_radar_camera.services.fusion.verifiers.base import GateResult

_NO_ROI: tuple[int, ...] = ()
# A track the camera showed beside the path stays beside it while no frame shows it for
# this long (an object passed close beside the ego leaves the image a few metres before
# the ego reaches it), unless its radar point comes this much nearer the path's centre.
BESIDE_CARRY_S = 0.5
BESIDE_CARRY_M = 0.1
# A track the camera put in the path stays there this long without a frame that shows
# it so again; the camera follows an object's surface toward the path this many windows.
INTO_CARRY_S = 0.3
INTO_WINDOWS = 3


@dataclass(frozen=True, slots=True)
class CycleResult:
    targets: VerifiedTargets
    command: BrakeCommand


@dataclass(slots=True)
class DecidedCycle:
    """A radar cycle whose command is decided: what `report` needs to describe it.
    `checked` holds the targets of the tracks the command needed, by confirmed index."""

    tracks: RadarTracks
    feeds: tuple[FrameFeed, ...]
    confirmed: list[RadarTrack]
    invalid: list[RadarTrack]
    status: VerifierStatus
    reason_unavailable: str
    age_ns: int
    now_mono_ns: int
    command: BrakeCommand
    kins: list[Kinematics] = field(default_factory=list)
    threats: list[tuple[Decision, str]] = field(default_factory=list)
    threat_order: list[int] = field(default_factory=list)     # confirmed indices
    threat_views: list[CameraView] = field(default_factory=list)
    checked: dict[int, VerifiedTarget] = field(default_factory=dict)
    cameras_unavailable: dict[str, str] = field(default_factory=dict)


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
        # A verifier may precompute per calibration (the depth verifier's ray maps): now,
        # not inside the first radar cycle that gates a track.
        prepare = getattr(verifier, "prepare", None)
        if callable(prepare):
            for cam in self.cameras:
                prepare(cam.projector.cal)
        self.source = f"fusion/{settings.instance}"
        self.hold = BrakeHold(round(settings.decision.hold_s * 1e9))
        kinematic = settings.decision.rule is RuleName.KINEMATIC
        self.rule: DecisionRule | KinematicRule = (
            KinematicRule(settings.decision) if kinematic else DecisionRule(settings.decision))
        self.stage = CommandStage(settings.decision, self.hold,
                                  self.rule if isinstance(self.rule, KinematicRule) else None)
        # `vehicle/motion` and `vehicle/driver` (`on_vehicle`); only the kinematic rule
        # reads them.
        vs = settings.vehicle_state
        self.vehicle = VehicleState(vs.stamp_check, vs.max_age_s)
        p = settings.decision.corridor.prediction
        # Per-track memory of sideways motion, for path prediction (None when it is off).
        self.lateral = (LateralMotion(p.min_lateral_speed_mps, p.confirm_cycles)
                        if self.rule.predict else None)
        self._moving: set[int] = set()     # this cycle's tracks moving sideways
        # Per-track evidence of verifiers that report a per-frame llr (None when off).
        self.evidence = (TrackEvidence(settings.evidence) if settings.evidence.enabled
                         else None)
        self._gathers = self.evidence is not None and bool(
            getattr(verifier, "gives_llr", False))
        # Per track, the last frame that showed its object beside the path: (radar stamp,
        # the radar point's offset from the path then, the reason); forgotten once older
        # than BESIDE_CARRY_S, at the start of a cycle.
        self._beside: dict[int, tuple[int, float, str]] = {}
        self.beside_path_targets = 0   # threats the camera took out of the path, since start
        # Per track the point test leaves out of the path, the last frame that showed its
        # object's surface running into it: (radar stamp, why).
        self._into: dict[int, tuple[int, str]] = {}
        # Tracks in range the road's edge took out of the path where they reached a stage
        # (each cycle counts), since start.
        self.road_edge_targets = 0
        self._seq = 0
        self.invalid_tracks = 0    # confirmed tracks with non-finite numbers, since start
        self._max_skew_ns = round(settings.frames.max_skew_s * 1e9)
        self._frozen_after_ns = round(settings.frames.frozen_after_s * 1e9)
        self.frozen_cycles: dict[str, int] = {}   # cycles a camera was judged frozen
        self._radar_max_age_ns = round(settings.decision.radar_max_age_s * 1e9)

    def on_vehicle(self, msg: EgoMotion | DriverInputs, now_wall_ns: int,
                   now_mono_ns: int) -> bool:
        """A `vehicle/motion` or `vehicle/driver` sample arrived (common/vehicle_state.py:
        late and out-of-order samples are counted and not taken); True when taken."""
        if isinstance(msg, EgoMotion):
            return self.vehicle.motion.observe(msg, now_mono_ns, now_wall_ns)
        return self.vehicle.driver.observe(msg, now_mono_ns, now_wall_ns)

    def process(self, tracks: RadarTracks, feeds: FrameFeed | Sequence[FrameFeed],
                now_wall_ns: int, now_mono_ns: int,
                vehicle: VehicleSample | None = None) -> CycleResult:
        """One radar cycle, decided and reported (`decide`, then `report`).
        Raises ValueError when the number of feeds is not the number of cameras."""
        decided = self.decide(tracks, feeds, now_wall_ns, now_mono_ns, vehicle)
        return CycleResult(self.report(decided), decided.command)

    def decide(self, tracks: RadarTracks, feeds: FrameFeed | Sequence[FrameFeed],
               now_wall_ns: int, now_mono_ns: int,
               vehicle: VehicleSample | None = None) -> DecidedCycle:
        """The cycle's BrakeCommand (`.command`), checking only the tracks it depends on.
        `feeds`: each camera's frames, in camera order (one FrameFeed for a single
        camera). `now_wall_ns` judges the radar's age; `now_mono_ns` stamps the messages'
        pub_mono_ns (the shell refreshes it at publish) and judges the vehicle state's.
        `vehicle`: the vehicle's state for this cycle (None: `self.vehicle`, as
        `on_vehicle` filled it, at `now_mono_ns`); only the kinematic rule reads it.
        Raises ValueError when the number of feeds is not the number of cameras."""
        feeds = (feeds,) if isinstance(feeds, FrameFeed) else tuple(feeds)
        if len(feeds) != len(self.cameras):
            raise ValueError(f"{len(feeds)} frame feeds for {len(self.cameras)} cameras")
        confirmed: list[RadarTrack] = []
        invalid: list[RadarTrack] = []
        for t in tracks.tracks:
            if t.confirmed:
                (confirmed if finite_track(t) else invalid).append(t)
        self.invalid_tracks += len(invalid)
        if isinstance(self.rule, KinematicRule):
            sample = vehicle if vehicle is not None else self.vehicle.sample(now_mono_ns)
            self.rule.begin(sample, confirmed, tracks.header.stamp_ns)
            lateral_input = self.rule.lateral_input(confirmed)
        else:
            lateral_input = confirmed
        self._moving = self.lateral.update(lateral_input) if self.lateral is not None else set()
        if self.evidence is not None:
            self.evidence.forget_older(tracks.header.stamp_ns)
        carry_ns = BESIDE_CARRY_S * 1e9
        for i in [i for i, b in self._beside.items()
                  if tracks.header.stamp_ns - b[0] > carry_ns]:
            del self._beside[i]
        age_ns = now_wall_ns - tracks.header.stamp_ns
        # A stamp from the future beyond the bound means unsynchronised clocks: the age
        # is unknown, so the cycle is treated as stale.
        if abs(age_ns) > self._radar_max_age_ns:
            stale = {i: self._stale_target(t, age_ns) for i, t in enumerate(confirmed)}
            command = self._command(tracks, list(stale.values()), VerifierStatus.STALE_RADAR,
                                    "", age_ns, now_wall_ns, now_mono_ns,
                                    confirmed=confirmed)
            return DecidedCycle(tracks, feeds, confirmed, invalid, VerifierStatus.STALE_RADAR,
                                "", age_ns, now_mono_ns, command, checked=stale)
        feeds = self._usable(feeds, confirmed)
        kins = [self._kinematics(t) for t in confirmed]
        threats = [self.rule.threat(k) for k in kins]
        if isinstance(self.rule, KinematicRule):
            rule = self.rule
            self.road_edge_targets += sum(1 for k in kins if k.road_edge and k.in_range
                                          and rule.stage(k) is not None)
        ranks = [_rank(threat, k.ttc_eff_s, k.level_pct)
                 for (threat, _), k in zip(threats, kins, strict=True)]
        order = sorted((i for i in range(len(confirmed)) if threats[i][0] is not Decision.NONE),
                       key=ranks.__getitem__, reverse=True)
        views = camera_views(self.cameras, feeds, [confirmed[i] for i in order],
                             tracks.header.stamp_ns, self._max_skew_ns, self.s.frames.align,
                             self.verifier.needs_depth)
        reason_unavailable = ""
        if any(v.frame is not None for v in views):
            status = VerifierStatus.OK
        else:
            status = VerifierStatus.UNAVAILABLE
            reason_unavailable = _reasons(views)
        checked: dict[int, VerifiedTarget] = {}
        best_rank = _rank(Decision.NONE, None)
        for j, i in enumerate(order):
            if ranks[i] <= best_rank:
                break                    # neither this threat nor any after it can win
            tgt = self._target(confirmed[i], kins[i], threats[i], views, j,
                               tracks.header.stamp_ns, gate=True)
            checked[i] = tgt
            if tgt.decision is not Decision.NONE:
                best_rank = max(best_rank, _rank_of(tgt))
        command = self._command(tracks, list(checked.values()), status, reason_unavailable,
                                age_ns, now_wall_ns, now_mono_ns, confirmed=confirmed)
        return DecidedCycle(
            tracks, feeds, confirmed, invalid, status, reason_unavailable, age_ns,
            now_mono_ns, command, kins, threats, order, views, checked,
            {v.name: v.reason for v in views if v.frame is None})

    def report(self, cycle: DecidedCycle) -> VerifiedTargets:
        """Every confirmed track of a decided cycle as a target, in track order, then the
        invalid ones: the threats the command did not need are gated now, the other tracks
        only with `gate_scope = "all"`."""
        targets = dict(cycle.checked)
        stamp_ns = cycle.tracks.header.stamp_ns
        if cycle.status is not VerifierStatus.STALE_RADAR:
            for j, i in enumerate(cycle.threat_order):
                if i not in targets:
                    targets[i] = self._target(cycle.confirmed[i], cycle.kins[i],
                                              cycle.threats[i], cycle.threat_views, j,
                                              stamp_ns, gate=True)
            others = [i for i in range(len(cycle.confirmed)) if i not in targets]
            views = camera_views(self.cameras, cycle.feeds,
                                 [cycle.confirmed[i] for i in others], stamp_ns,
                                 self._max_skew_ns, self.s.frames.align,
                                 self.verifier.needs_depth)
            gate_all = self.s.gate_scope is GateScope.ALL
            for j, i in enumerate(others):
                # A verifier whose evidence adds up checks every closing track in range
                # too: a track that becomes a threat only once it has left the image (a
                # cyclist crossing close ahead) has the evidence of when it was seen.
                k = cycle.kins[i]
                gather = self._gathers and k.in_range and k.ttc_s is not None
                targets[i] = self._target(cycle.confirmed[i], k, cycle.threats[i],
                                          views, j, stamp_ns, gate=gate_all or gather)
            self._follow_into_path(cycle, targets, stamp_ns)
        feeds = cycle.feeds
        header = Header(seq=cycle.command.header.seq, source=self.source, stamp_ns=stamp_ns,
                        pub_mono_ns=cycle.now_mono_ns)
        return self._with_vehicle(VerifiedTargets(
            header=header, instance=self.s.instance, radar_sensor=cycle.tracks.sensor,
            radar_seq=cycle.tracks.header.seq, verifier=self.verifier.name,
            verifier_params=self.verifier_params, verifier_status=cycle.status,
            targets=(*(targets[i] for i in range(len(cycle.confirmed))),
                     *(_invalid_target(t) for t in cycle.invalid)),
            processing_ns=0, camera=self.camera_names,
            unavailable_reason=cycle.reason_unavailable, radar_age_ms=cycle.age_ns / 1e6,
            frames_received=sum(f.received for f in feeds),
            frames_undecodable=sum(f.undecodable for f in feeds),
            frames_dropped=sum(f.dropped for f in feeds),
            frames_corrupt=sum(f.corrupt for f in feeds),
            cameras_unavailable=cycle.cameras_unavailable, override=cycle.command.override))

    def _follow_into_path(self, cycle: DecidedCycle, targets: Mapping[int, VerifiedTarget],
                          stamp_ns: int) -> None:
        """For each checked track the point test leaves out of the path whose object's
        surface at the range runs up to the window's edge on the path's side, the camera
        looks in the window beside it, and on, up to INTO_WINDOWS
        (KinematicRule.into_path_next, into_path): a track whose surface runs into the path
        is in it from the next cycle on, while frames keep showing it so (or for
        INTO_CARRY_S without a frame)."""
        for i in [i for i, v in self._into.items() if stamp_ns - v[0] > INTO_CARRY_S * 1e9]:
            del self._into[i]
        rule = self.rule
        if not isinstance(rule, KinematicRule) or not self._gathers:
            return
        for i, tgt in targets.items():
            if tgt.score_name == "":
                continue                      # no frame this cycle: the memory carries
            t, k = cycle.confirmed[i], cycle.kins[i]
            step = rule.into_path_next(t.track_id, k, tgt.gate_detail)
            why: str | None = None
            dy = 0.0
            for _ in range(INTO_WINDOWS):
                if step is None:
                    break
                dy += step
                detail = self._probe(cycle, t, dy, stamp_ns)
                if detail is None:
                    break
                why, step = rule.into_path(tgt.x_m, detail, 1 if step > 0 else -1)
            if why is not None:
                self._into[t.track_id] = (stamp_ns, why)
            else:
                self._into.pop(t.track_id, None)

    def _probe(self, cycle: DecidedCycle, t: RadarTrack, dy_m: float,
               stamp_ns: int) -> Mapping[str, float] | None:
        """The check's detail `dy_m` sideways of track `t` at its range (no evidence
        kept: it looks at a place, not at the track), None without a frame."""
        y = t.y_m + dy_m
        probe = msgspec.structs.replace(t, y_m=y, range_m=math.hypot(t.x_m, y))
        views = camera_views(self.cameras, cycle.feeds, [probe], stamp_ns, self._max_skew_ns,
                             self.s.frames.align, self.verifier.needs_depth)
        result = check_track(0, views, True, self.verifier.verify).result
        return result.detail if result is not None else None

    def _with_vehicle(self, targets: VerifiedTargets) -> VerifiedTargets:
        """With the vehicle's state as the kinematic rule used it this cycle (unchanged
        under the paper's rule)."""
        rule = self.rule
        if not isinstance(rule, KinematicRule):
            return targets
        motion = rule.vehicle.motion if rule.vehicle is not None else None
        return msgspec.structs.replace(
            targets, ego_speed_mps=motion.speed_mps if motion is not None else None,
            ego_yaw_rate_dps=motion.yaw_rate_dps if motion is not None else None,
            path=rule.path.describe(), vehicle_state=rule.degraded,
            path_curvature_per_m=rule.path.curvature_per_m, range_gate_m=rule.max_range)

    def _usable(self, feeds: tuple[FrameFeed, ...],
                confirmed: list[RadarTrack]) -> tuple[FrameFeed, ...]:
        """The feeds with each frozen camera marked unusable (counted in `frozen_cycles`,
        by camera): one picture for `frozen_after_s` while the tracks say it must have
        changed. The tracks are projected only for a camera whose picture stood that long."""
        out = []
        for cam, feed in zip(self.cameras, feeds, strict=True):
            still_ns = unchanged_for_ns(feed)
            if self._frozen_after_ns and still_ns is not None \
                    and still_ns >= self._frozen_after_ns:
                span_ns = min(still_ns, EXPECTED_CHANGE_SPAN * self._frozen_after_ns)
                change = expected_change_px(cam.projector, confirmed, span_ns)
                if frozen(feed, change, self._frozen_after_ns):
                    self.frozen_cycles[cam.name] = self.frozen_cycles.get(cam.name, 0) + 1
                    feed = replace(feed, unusable_reason=FROZEN_REASON)
            out.append(feed)
        return tuple(out)

    def _kinematics(self, t: RadarTrack) -> Kinematics:
        k = self.rule.kinematics(t, t.track_id in self._moving)
        into = self._into.get(t.track_id)
        if into is not None and not k.in_path and k.window is None and not k.road_edge:
            k = replace(k, in_path=True, by_camera=into[1])
        return k

    def _stale_target(self, t: RadarTrack, age_ns: int) -> VerifiedTarget:
        k = self._kinematics(t)
        reason = (f"radar stale (age {age_ns / 1e6:.0f} ms, max "
                  f"{self._radar_max_age_ns / 1e6:.0f} ms)")
        return VerifiedTarget(
            track_id=t.track_id, x_m=t.x_m, y_m=t.y_m, range_m=t.range_m,
            range_rate_mps=t.range_rate_mps, in_path=k.in_path,
            verification=Verification.NOT_CHECKED, roi_xywh=_NO_ROI, density=None,
            ttc_s=k.ttc_s, ttc_eff_s=k.ttc_eff_s, decision=Decision.NONE, reason=reason,
            frame_seq=None, frame_age_ms=None, path_predicted=k.window is not None)

    def _target(self, t: RadarTrack, k: Kinematics, threat: tuple[Decision, str],
                views: list[CameraView], j: int, radar_stamp_ns: int,
                gate: bool) -> VerifiedTarget:
        """Track `t`, the `j`-th of the tracks `views` were projected for, checked in the
        cameras (gated iff `gate`) and decided."""
        decision, reason = threat
        check = check_track(j, views, gate, self.verifier.verify)
        verification = check.verification
        result = check.result
        detail = result.detail if result is not None else {}
        if result is not None and self.evidence is not None and LLR_KEY in detail:
            total = self.evidence.add(t.track_id, detail[LLR_KEY], radar_stamp_ns,
                                      (t.x_m, t.y_m))
            detail = {**detail, EVIDENCE_KEY: total}
            # A frame that cannot tell leaves a track the evidence has confirmed
            # confirmed: one frame of sparse depth does not undo it.
            verification = (Verification.REJECTED if self.evidence.vetoed(total)
                            else Verification.UNAVAILABLE if result.unverifiable
                            and total <= 0.0
                            else Verification.VERIFIED)
        elif result is not None and result.unverifiable:
            verification = Verification.UNAVAILABLE
        elif (result is None and gate and self._gathers and self.evidence is not None
              and verification in (Verification.NOT_VISIBLE, Verification.UNAVAILABLE)):
            # No frame shows the track now: the evidence gathered so far decides.
            carried = self.evidence.carried(t.track_id, (t.x_m, t.y_m), radar_stamp_ns)
            if carried is not None and carried != 0.0:
                detail = {EVIDENCE_KEY: carried, EVIDENCE_CARRIED_KEY: 1.0}
                verification = (Verification.REJECTED if self.evidence.vetoed(carried)
                                else Verification.VERIFIED if carried > 0 else verification)
        density = result.score if result is not None else None
        cannot_tell = (verification is Verification.UNAVAILABLE and result is not None
                       and result.unverifiable)
        if cannot_tell:
            detail = {**detail, CANNOT_TELL_KEY: 1.0}
        if verification is Verification.UNAVAILABLE and decision is not Decision.NONE:
            why = (_reasons(views, j) if not cannot_tell
                   else "camera cannot tell: " + ", ".join(
                       name for name, v in detail.items() if name.startswith("depth_") and v))
            reason = f"{reason}; {why}"
        rule = self.rule
        outside = verification is Verification.NOT_VISIBLE
        if isinstance(rule, KinematicRule) and ((cannot_tell and rule.cannot_tell_full_only)
                                                or (outside and rule.not_visible_full_only)):
            decision, reason = rule.cannot_tell(
                k, decision, reason,
                "outside the camera's view" if outside else "camera cannot tell")
        else:
            decision, reason = decide(decision, reason, verification, rule.policy)
        if k.road_edge:
            detail = {**detail, ROAD_EDGE: 1.0}
        if k.by_camera:
            detail = {**detail, INTO_PATH: 1.0}
        if isinstance(rule, KinematicRule):
            decision, reason, detail = self._beside_path(t, k, check.view, j, result,
                                                         decision, reason, detail,
                                                         radar_stamp_ns)
        score_name = result.score_name if result is not None else ""
        if verification is Verification.REJECTED:
            # No frame this cycle (a veto carried by the evidence): no score to give.
            parts = [f"{score_name} {density:.4f}"] if density is not None else []
            if EVIDENCE_KEY in detail:
                parts.append(f"evidence {detail[EVIDENCE_KEY]:.2f}"
                             + (" carried" if EVIDENCE_CARRIED_KEY in detail else ""))
            reason = "; ".join([reason, ", ".join(parts)]) if parts else reason
        # Where a track no camera sees is reported: the first camera with a frame.
        view = check.view or next((v for v in views if v.frame is not None), views[0])
        frame = view.frame
        x, y = view.xy[j]
        return VerifiedTarget(
            track_id=t.track_id, x_m=x, y_m=y, range_m=t.range_m,
            range_rate_mps=t.range_rate_mps, in_path=k.in_path, verification=verification,
            roi_xywh=(_NO_ROI if check.roi is None or verification is Verification.UNAVAILABLE
                      else tuple(check.roi)),
            density=density, ttc_s=k.ttc_s, ttc_eff_s=k.ttc_eff_s, decision=decision,
            reason=reason, frame_seq=frame.seq if frame is not None else None,
            frame_age_ms=((radar_stamp_ns - frame.stamp_ns) / 1e6 if frame is not None
                          else None),
            gate_detail=detail,
            path_predicted=k.window is not None,
            camera=check.view.name if check.view is not None else "",
            cameras=check.per_camera, score_name=score_name, **_kinematic_fields(k))

    def _beside_path(self, t: RadarTrack, k: Kinematics, view: CameraView | None, j: int,
                     result: GateResult | None, decision: Decision, reason: str,
                     detail: Mapping[str, float], stamp_ns: int
                     ) -> tuple[Decision, str, dict[str, float]]:
        """The threat `decision` unless the camera shows the track's object beside the
        path (KinematicRule.beside_path) in this frame, or in the last frame that showed
        it while no frame shows it now, or one shows only part of its window without
        pixels at the range near the path (an object passed close beside the ego leaves
        the image before the ego reaches it), within BESIDE_CARRY_S and no nearer the
        path's centre than it was then."""
        rule = self.rule
        assert isinstance(rule, KinematicRule)
        offset = k.path_point.d_m if k.path_point is not None else k.lateral_m
        beside: str | None = None
        shown = False
        if result is not None and view is not None:
            x = view.xy[j][0]
            beside = rule.beside_path(k, x, detail)
            # A frame with only part of the window in the image (the object leaving it)
            # and no pixels at the range near the path shows no more than no frame.
            shown = (detail.get(IN_VIEW, 1.0) >= 1.0 or beside is not None
                     or rule.camera_reaches_path(x, detail))
            if beside is not None:
                self._beside[t.track_id] = (stamp_ns, offset, beside)
            elif shown:
                self._beside.pop(t.track_id, None)
        if not shown and k.window is None and t.track_id in self._beside:
            then_ns, then, why = self._beside[t.track_id]
            if (stamp_ns - then_ns <= BESIDE_CARRY_S * 1e9 and offset * then > 0.0
                    and abs(offset) >= abs(then) - BESIDE_CARRY_M):
                beside = f"{why} (last seen {(stamp_ns - then_ns) / 1e6:.0f} ms ago)"
        if beside is None or decision is Decision.NONE:
            return decision, reason, dict(detail)
        self.beside_path_targets += 1
        return Decision.NONE, beside, {**detail, BESIDE_PATH: 1.0}

    def failed_cycle(self, tracks: RadarTracks, error: str, now_wall_ns: int,
                     now_mono_ns: int) -> CycleResult:
        """The cycle's command when deciding raised: still exactly one command (NONE, or
        the held BRAKE), the verifier unavailable, the error as the reason."""
        reason = f"fusion error: {error}"
        command = self._command(tracks, [], VerifierStatus.UNAVAILABLE, reason,
                                now_wall_ns - tracks.header.stamp_ns, now_wall_ns,
                                now_mono_ns, summary=reason)
        return CycleResult(self.failed_report(tracks, command, error, now_wall_ns, now_mono_ns),
                           command)

    def failed_report(self, tracks: RadarTracks, command: BrakeCommand, error: str,
                      now_wall_ns: int, now_mono_ns: int) -> VerifiedTargets:
        """The targets of a cycle whose processing raised after `command` was decided: no
        target, the verifier unavailable, the error as the reason. Changes no state."""
        age_ns = now_wall_ns - tracks.header.stamp_ns
        header = Header(seq=command.header.seq, source=self.source,
                        stamp_ns=tracks.header.stamp_ns, pub_mono_ns=now_mono_ns)
        return VerifiedTargets(
            header=header, instance=self.s.instance, radar_sensor=tracks.sensor,
            radar_seq=tracks.header.seq, verifier=self.verifier.name,
            verifier_params=self.verifier_params, verifier_status=VerifierStatus.UNAVAILABLE,
            targets=(), processing_ns=0, camera=self.camera_names,
            unavailable_reason=f"fusion error: {error}", radar_age_ms=age_ns / 1e6)

    def _command(self, tracks: RadarTracks, targets: list[VerifiedTarget],
                 status: VerifierStatus, reason_unavailable: str, age_ns: int,
                 now_wall_ns: int, now_mono_ns: int, summary: str = "",
                 confirmed: Sequence[RadarTrack] = ()) -> BrakeCommand:
        """The command from the most severe of `targets` (ties: smallest TTC_eff, then the
        first), and the hold. `confirmed`: every confirmed track (counted in the reason; a
        held track's current range and TTC)."""
        worst = max(targets, key=_rank_of, default=None)
        decision = worst.decision if worst is not None else Decision.NONE
        n_targets = max(len(targets), len(confirmed))
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
        level = worst.brake_level_pct if worst is not None else None
        staged = self.stage.update(decision, level, track_id, now_wall_ns)
        held = staged.held
        if staged.note:
            reason = f"{staged.note}; this cycle: {decision.value}, {reason}"
        elif held:
            left_ms = self.hold.remaining_ns(now_wall_ns) / 1e6
            reason = f"BRAKE held {left_ms:.0f} ms more; this cycle: {decision.value}, {reason}"
        if held and decision is not Decision.BRAKE:
            track_id = self.hold.track_id
            # The held track as the radar sees it now, if it is still there.
            now = next((t for t in confirmed if t.track_id == track_id), None)
            range_m = now.range_m if now is not None else None
            ttc_s = self._kinematics(now).ttc_s if now is not None else None
        decision = staged.decision
        seq = self._seq
        self._seq += 1
        return BrakeCommand(
            header=Header(seq=seq, source=self.source, stamp_ns=tracks.header.stamp_ns,
                          pub_mono_ns=now_mono_ns),
            instance=self.s.instance, decision=decision,
            brake_level_pct=staged.level_pct if decision is Decision.BRAKE else 0.0,
            verifier_status=status, held=held, track_id=track_id, range_m=range_m,
            ttc_s=ttc_s, reason=reason, radar_seq=tracks.header.seq,
            radar_last_frame_mono_ns=tracks.last_frame_mono_ns, override=staged.override)


def _kinematic_fields(k: Kinematics) -> dict[str, float | None]:
    """A target's kinematic-rule figures (none under the paper's rule)."""
    if k.path_point is None:
        return {}
    return dict(brake_level_pct=k.level_pct, required_decel_mps2=k.required_decel_mps2,
                accel_mps2=k.accel_mps2, path_s_m=k.path_point.s_m, path_d_m=k.path_point.d_m)


def _reasons(views: list[CameraView], track: int | None = None) -> str:
    """Why the cameras (that would see `track`, or all) have no usable frame; one camera:
    its reason alone, as before there were several."""
    missing = [v for v in views if v.frame is None
               and (track is None or v.rois[track] is not None)]
    if len(views) == 1:
        return missing[0].reason if missing else ""
    return "; ".join(f"{v.name}: {v.reason}" for v in missing)


def finite_track(t: RadarTrack) -> bool:
    """Are a track's position, velocity and range all finite numbers? Fusion decides only
    on confirmed tracks that are; the others it reports as invalid."""
    return all(map(math.isfinite, (t.x_m, t.y_m, t.vx_mps, t.vy_mps, t.range_m,
                                   t.range_rate_mps)))


def _invalid_target(t: RadarTrack) -> VerifiedTarget:
    """A confirmed track with NaN or infinite numbers: reported, never decided on."""
    return VerifiedTarget(
        track_id=t.track_id, x_m=t.x_m, y_m=t.y_m, range_m=t.range_m,
        range_rate_mps=t.range_rate_mps, in_path=False, verification=Verification.NOT_CHECKED,
        roi_xywh=_NO_ROI, density=None, ttc_s=None, ttc_eff_s=None, decision=Decision.NONE,
        reason="invalid track: non-finite position, velocity or range", frame_seq=None,
        frame_age_ms=None)


def _rank(decision: Decision, ttc_eff_s: float | None,
          level_pct: float | None = None) -> tuple[int, float, float]:
    """Orders decisions by severity (a BRAKE by its level), then urgency: the higher, the
    more severe."""
    level = level_pct or 0.0 if decision is Decision.BRAKE else 0.0
    return severity(decision), level, -(ttc_eff_s if ttc_eff_s is not None else math.inf)


def _rank_of(target: VerifiedTarget) -> tuple[int, float, float]:
    return _rank(target.decision, target.ttc_eff_s, target.brake_level_pct)
