"""Shared by the brake tests: commands as fusion would publish them, signed with a test
key (a fixed secret: for tests only)."""

from pathlib import Path

from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.command_auth import CommandKey, CommandSigner, write_key
from aeb_radar_camera.common.messages import BrakeCommand, Decision, Header, VerifierStatus, encode

TEST_KEY = CommandKey("primary-test", "primary", bytes(range(32)))
SIGNER = CommandSigner(TEST_KEY, session=1)


def keyring() -> dict[str, CommandKey]:
    return {TEST_KEY.key_id: TEST_KEY}


def write_test_key(folder: Path, key: CommandKey = TEST_KEY) -> Path:
    """The key as a key file in `folder` (for a brake or publisher process)."""
    path = folder / f"{key.key_id}.key"
    if not path.exists():
        write_key(path, key)
    return path


def command(
    seq: int,
    level: float = 0.0,
    instance: str = "primary",
    pub_mono_ns: int | None = None,
    stamp_ns: int | None = None,
    decision: Decision | None = None,
    radar_last_frame_mono_ns: int | None = None,
) -> BrakeCommand:
    """BRAKE at `level` when level > 0, else NONE; stamps default to now (the radar's
    last frame: the publish time)."""
    if decision is None:
        decision = Decision.BRAKE if level > 0 else Decision.NONE
    now_mono = mono_ns() if pub_mono_ns is None else pub_mono_ns
    return BrakeCommand(
        header=Header(seq=seq, source=f"fusion/{instance}",
                      stamp_ns=wall_ns() if stamp_ns is None else stamp_ns,
                      pub_mono_ns=now_mono),
        instance=instance, decision=decision, brake_level_pct=level,
        verifier_status=VerifierStatus.OK, held=False, track_id=7 if level else -1,
        range_m=8.0 if level else None, ttc_s=1.2 if level else None, reason="test",
        radar_seq=seq, radar_last_frame_mono_ns=(
            now_mono if radar_last_frame_mono_ns is None else radar_last_frame_mono_ns),
    )


def payload(seq: int, level: float = 0.0, signer: CommandSigner | None = SIGNER,
            **kw: object) -> bytes:
    """The command signed by `signer` (None: unsigned, as an intruder would send it)."""
    cmd = command(seq, level, **kw)  # type: ignore[arg-type]
    return encode(cmd) if signer is None else signer.sign(cmd)
