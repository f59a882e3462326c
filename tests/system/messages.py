"""Message factories for the system tests (valid messages with plausible values)."""

from aeb_radar_camera.common.messages import (
    BrakeCommand,
    BrakeState,
    BrakeStatus,
    Decision,
    FailsafePolicy,
    Header,
    OutputMode,
    RadarTrack,
    RadarTracks,
    Verification,
    VerifiedTarget,
    VerifiedTargets,
    VerifierStatus,
)


def header(seq: int, source: str, stamp_ns: int = 0, mono_ns: int = 0) -> Header:
    return Header(seq=seq, source=source, stamp_ns=stamp_ns, pub_mono_ns=mono_ns)


def track(track_id: int, x: float, y: float = 0.0, confirmed: bool = True) -> RadarTrack:
    return RadarTrack(track_id=track_id, x_m=x, y_m=y, vx_mps=-5.0, vy_mps=0.0,
                      range_m=(x * x + y * y) ** 0.5, range_rate_mps=-5.0, rcs_dbsm=5.0,
                      confirmed=confirmed, hits=5, misses=0, x_var_m2=0.1, y_var_m2=0.1)


def radar_tracks(seq: int, tracks: tuple[RadarTrack, ...], stamp_ns: int = 0,
                 mono_ns: int = 0) -> RadarTracks:
    return RadarTracks(header=header(seq, "radar/front", stamp_ns, mono_ns), sensor="front",
                       mode=OutputMode.OBJECTS, meas_counter=seq, complete=True,
                       n_detections=len(tracks), n_prefiltered=len(tracks),
                       last_frame_mono_ns=mono_ns, processing_ns=150_000, tracks=tracks)


def brake_status(seq: int, state: BrakeState = BrakeState.ARMED, stamp_ns: int = 0,
                 mono_ns: int = 0) -> BrakeStatus:
    return BrakeStatus(header=header(seq, "brake/main", stamp_ns, mono_ns), state=state,
                       reason="commands arriving", instance="primary",
                       policy=FailsafePolicy.HOLD, last_cmd_seq=seq, commanded_level_pct=0.0,
                       actuator_position_pct=0.0, actuator_state="OK", actuator_connected=True,
                       cmd_to_serial_us=250.0, radar_to_serial_us=1800.0, rejected={},
                       counters={"acks": seq})


def target(track_id: int, range_m: float, decision: Decision, verification: Verification,
           density: float | None = 0.08, in_path: bool = True) -> VerifiedTarget:
    ttc = range_m / 5.0
    return VerifiedTarget(track_id=track_id, x_m=range_m, y_m=0.0, range_m=range_m,
                          range_rate_mps=-5.0, in_path=in_path, verification=verification,
                          roi_xywh=(100, 100, 50, 80), density=density, ttc_s=ttc,
                          ttc_eff_s=ttc - 1.0, decision=decision, reason="test",
                          frame_seq=1, frame_age_ms=10.0)


def verified_targets(instance: str, radar_seq: int, targets: tuple[VerifiedTarget, ...],
                     verifier: str = "edge_density", stamp_ns: int = 0) -> VerifiedTargets:
    return VerifiedTargets(header=header(radar_seq, f"fusion/{instance}", stamp_ns),
                           instance=instance, radar_sensor="front", radar_seq=radar_seq,
                           verifier=verifier, verifier_params={"tau": 0.025},
                           verifier_status=VerifierStatus.OK, targets=targets,
                           processing_ns=200_000)


def brake_command(instance: str, seq: int, radar_seq: int, decision: Decision,
                  stamp_ns: int = 0) -> BrakeCommand:
    return BrakeCommand(header=header(seq, f"fusion/{instance}", stamp_ns), instance=instance,
                        decision=decision,
                        brake_level_pct=100.0 if decision is Decision.BRAKE else 0.0,
                        verifier_status=VerifierStatus.OK, held=False, track_id=1,
                        range_m=10.0, ttc_s=2.0, reason="test", radar_seq=radar_seq,
                        radar_last_frame_mono_ns=0)
