"""Shared by the brake tests: commands as fusion would publish them."""

from common.clock import mono_ns, wall_ns
from common.messages import BrakeCommand, Decision, Header, VerifierStatus, encode


def command(
    seq: int,
    level: float = 0.0,
    instance: str = "primary",
    pub_mono_ns: int | None = None,
    stamp_ns: int | None = None,
    decision: Decision | None = None,
) -> BrakeCommand:
    """BRAKE at `level` when level > 0, else NONE; stamps default to now."""
    if decision is None:
        decision = Decision.BRAKE if level > 0 else Decision.NONE
    now_mono = mono_ns()
    return BrakeCommand(
        header=Header(seq=seq, source=f"fusion/{instance}",
                      stamp_ns=wall_ns() if stamp_ns is None else stamp_ns,
                      pub_mono_ns=now_mono if pub_mono_ns is None else pub_mono_ns),
        instance=instance, decision=decision, brake_level_pct=level,
        verifier_status=VerifierStatus.OK, held=False, track_id=7 if level else -1,
        range_m=8.0 if level else None, ttc_s=1.2 if level else None, reason="test",
        radar_seq=seq, radar_last_frame_mono_ns=now_mono,
    )


def payload(seq: int, level: float = 0.0, **kw: object) -> bytes:
    return encode(command(seq, level, **kw))  # type: ignore[arg-type]
