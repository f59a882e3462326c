"""The shell: one BrakeCommand per radar cycle, published before the targets, also when
the core fails half-way or the payload is not a radar cycle."""

import logging
from typing import Any

import pytest

from aeb_radar_camera.common.clock import mono_ns, wall_ns
from aeb_radar_camera.common.messages import BrakeCommand, Decision, VerifiedTargets, encode
from aeb_radar_camera.services.fusion.frames import FrameDecoder
from aeb_radar_camera.services.fusion.shell import FusionShell
from aeb_radar_camera.services.fusion.verifiers import GateResult
from tests.fusion.helpers import FixedVerifier, cycle, make_core, track
from tests.fusion.test_frames import compressed


class FakePublisher:
    def __init__(self, log: list, name: str) -> None:
        self.log, self.name = log, name

    def put(self, msg) -> None:
        self.log.append((self.name, msg))


class FakeBus:
    """Just what FusionShell needs to publish; no Zenoh."""

    def __init__(self) -> None:
        self.log: list = []

    def publisher(self, spec, **params):
        return FakePublisher(self.log, spec.name)


def shell_with(verifier, **fusion) -> tuple[FusionShell, FakeBus]:
    # A radar age bound no stall on a loaded machine reaches: these tests are about the
    # shell, not the clock.
    fusion.setdefault("decision", {"radar_max_age_s": 60.0})
    bus = FakeBus()
    core = make_core(verifier, **fusion)
    decoder = FrameDecoder(848, 480, logging.getLogger("test"))
    return FusionShell(bus, core.s, core, decoder, logging.getLogger("test")), bus  # type: ignore[arg-type]


def fresh(shell: FusionShell) -> int:
    """Decode a frame stamped now; its stamp, for the cycle it belongs to (stamped
    alike, a stalled decode cannot put the frame beyond max_skew_s)."""
    stamp = wall_ns()
    shell.decoder.decode_now(compressed(stamp_ns=stamp), 1)
    return stamp


def payload(*tracks, seq: int = 0, stamp_ns: int | None = None) -> bytes:
    return encode(cycle(*tracks, seq=seq, stamp_ns=wall_ns() if stamp_ns is None else stamp_ns))


def test_command_then_targets_for_each_cycle():
    shell, bus = shell_with(FixedVerifier())
    stamp = fresh(shell)
    shell.on_tracks_payload(payload(track(x=8.0, vx=-6.0), seq=0, stamp_ns=stamp), "k", 0)
    shell.on_tracks_payload(payload(seq=1), "k", 0)
    kinds = [name for name, _ in bus.log]
    assert kinds == ["fusion_brake_cmd", "fusion_targets"] * 2
    first: BrakeCommand = bus.log[0][1]
    assert first.decision is Decision.BRAKE and first.header.pub_mono_ns > 0
    targets: VerifiedTargets = bus.log[1][1]
    assert targets.processing_ns > 0 and targets.radar_seq == 0


def test_processing_ends_where_the_command_is_handed_to_zenoh_so_the_put_is_the_hops():
    class SlowPut(FakePublisher):
        def put(self, msg) -> None:
            until = mono_ns() + 200_000_000        # a put taking 200 ms
            while mono_ns() < until:
                pass
            super().put(msg)

    shell, bus = shell_with(FixedVerifier())
    shell._cmd_pub = SlowPut(bus.log, "fusion_brake_cmd")  # type: ignore[assignment]
    stamp = fresh(shell)
    rx = mono_ns()
    shell.on_tracks_payload(payload(track(x=8.0, vx=-6.0), stamp_ns=stamp), "k", rx)
    command, targets = bus.log[0][1], bus.log[1][1]
    assert targets.processing_ns == command.header.pub_mono_ns - rx
    assert targets.processing_ns < 200_000_000 < mono_ns() - rx


def test_a_failure_half_way_through_a_cycle_sends_one_command_and_counts_it():
    calls = []

    class Breaks(FixedVerifier):
        def verify(self, obs):
            calls.append(obs.roi)
            if len(calls) > 1:
                raise RuntimeError("bug in a verifier")
            return GateResult(0.001, False)

    shell, bus = shell_with(Breaks())
    stamp = fresh(shell)
    # Most urgent first: rejected, so the next threat is gated, and that gate run raises.
    shell.on_tracks_payload(payload(track(tid=1, x=12.0, vx=-5.0),
                                    track(tid=2, x=6.0, vx=-5.0), stamp_ns=stamp), "k", 0)
    assert [name for name, _ in bus.log] == ["fusion_brake_cmd", "fusion_targets"]
    command, targets = bus.log[0][1], bus.log[1][1]
    assert command.decision is Decision.NONE and "bug in a verifier" in command.reason
    assert "fusion error" in targets.unavailable_reason
    assert shell.counters.get("processing_error") == 1


def test_a_failing_verifier_sends_a_none_command_with_the_error():
    class Broken(FixedVerifier):
        def verify(self, obs):
            raise RuntimeError("boom")

    shell, bus = shell_with(Broken())
    stamp = fresh(shell)
    shell.on_tracks_payload(payload(track(x=8.0, vx=-6.0), stamp_ns=stamp), "k", 0)
    commands = [m for name, m in bus.log if name == "fusion_brake_cmd"]
    assert len(commands) == 1 and commands[0].decision is Decision.NONE
    assert "fusion error: RuntimeError('boom')" in commands[0].reason


@pytest.mark.parametrize("junk", [b"", b"\x01\x02", encode(track())])
def test_a_payload_that_is_not_a_radar_cycle_is_counted_not_answered(junk):
    shell, bus = shell_with(FixedVerifier())
    assert shell.on_tracks_payload(junk, "k", 0) is None
    assert bus.log == [] and shell.counters.get("radar_undecodable") == 1


def test_radar_sequence_gaps_and_regressions_are_counted_and_still_answered():
    shell, bus = shell_with(FixedVerifier())
    for seq in (5, 6, 9, 9, 3):
        shell.on_tracks_payload(payload(seq=seq), "k", 0)
    assert shell.counters.get("radar_cycles_missed") == 2
    assert shell.counters.get("radar_seq_not_increasing") == 2
    assert [m.header.seq for name, m in bus.log if name == "fusion_brake_cmd"] == [0, 1, 2, 3, 4]


def test_a_forged_sequence_far_ahead_is_a_jump_not_a_trillion_missed_cycles():
    """A flood's sample numbered 2^40 must not make the missed-cycle count meaningless."""
    shell, bus = shell_with(FixedVerifier())
    for seq in (5, 7, 1 << 40, 8, 9):
        shell.on_tracks_payload(payload(seq=seq), "k", 0)
    assert shell.counters.get("radar_cycles_missed") == 1
    assert shell.counters.get("radar_seq_jumps") == 1
    assert shell.counters.get("radar_seq_not_increasing") == 1
    assert len([m for name, m in bus.log if name == "fusion_brake_cmd"]) == 5


def test_a_camera_calibration_other_than_ours_is_counted_and_named():
    import numpy as np

    from aeb_radar_camera.common.messages import CameraInfo, Header
    from aeb_radar_camera.services.fusion.camera_check import calibration_differences
    from tests.fusion.helpers import CAL

    def info(**over) -> CameraInfo:
        fields: dict[str, Any] = dict(
            header=Header(seq=0, source="camera/front", stamp_ns=0, pub_mono_ns=0),
            camera="front", width=848, height=480, k=tuple(CAL.k.ravel()), dist=(0.0,) * 5,
            r=tuple(CAL.r.ravel()), t_m=tuple(CAL.t), fps=30.0, source="folder",
            frames_published=0, frames_dropped=0, read_errors=0, healthy=True, status="")
        fields.update(over)
        return CameraInfo(**fields)

    assert calibration_differences(CAL, info()) == []
    assert calibration_differences(CAL, info(dist=())) == []          # zeros or none
    moved = np.asarray(CAL.t) + np.array([0.0, 0.0, 0.05])
    assert calibration_differences(CAL, info(t_m=tuple(moved), width=640)) == [
        "size 640x480 != 848x480", "t differs"]
    shell, _ = shell_with(FixedVerifier())
    shell.calibrations = {"front": CAL}
    shell.on_camera_info(info(), "k")
    shell.on_camera_info(info(k=(1.0,) * 9), "k")
    assert shell.counters.get("camera_calibration_mismatch") == 1
