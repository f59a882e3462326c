"""The brake's I/O shell in this process, on the simulated actuator's pty and no bus."""

import logging
from pathlib import Path

import pytest

from aeb_radar_camera.common.config.brake import BrakeConfig, BrakeSettings, SerialSettings
from aeb_radar_camera.common.messages import BrakeState
from aeb_radar_camera.services.brake.core import Outgoing
from aeb_radar_camera.services.brake.protocol import SEQ_MODULO, Command, HostMode, decode, encode
from aeb_radar_camera.services.brake.shell import BrakeShell, LineAhead, next_frame
from aeb_radar_camera.tools.sim.actuator import SimActuator
from tests.brake.helpers import keyring
from tests.support import wait_for


def test_a_failing_timer_tick_is_counted_and_the_deadline_still_holds(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    link = tmp_path / "actuator"
    sim, pair = SimActuator.on_pty(link)
    sim.start()
    cfg = BrakeConfig(brake=BrakeSettings(serial=SerialSettings(port=str(link))))
    shell = BrakeShell(cfg, logging.getLogger("test_shell"), keys=keyring())
    real_tick = shell.core.on_tick
    ticks: list[int] = []

    def first_tick_fails(now: int) -> Outgoing | None:
        ticks.append(now)
        if len(ticks) == 1:
            raise RuntimeError("a bug in the tick")
        return real_tick(now)

    monkeypatch.setattr(shell.core, "on_tick", first_tick_fails)
    shell.start()
    try:
        wait_for(lambda: shell.errors["timer_tick_failed"] == 1 and len(ticks) > 1, 10,
                 what="ticks after the failing one")
        # no command ever came: the deadline check still runs and enters FAILSAFE
        wait_for(lambda: shell.core.command_state is BrakeState.FAILSAFE, 10,
                 what="FAILSAFE")
        assert shell.errors["timer_tick_failed"] == 1
        assert shell.core.counters["deadline_misses"] >= 1
    finally:
        shell.stop()
        sim.stop()
        pair.remove()


def test_a_line_built_ahead_is_written_only_for_its_own_frame(monkeypatch: pytest.MonkeyPatch):
    import aeb_radar_camera.services.brake.shell as shell_module

    built: list[Command] = []

    def counting(frame: Command) -> bytes:
        built.append(frame)
        return encode(frame)

    monkeypatch.setattr(shell_module, "encode", counting)
    lines = LineAhead()
    armed = Command(7, 0, 250, HostMode.ARMED)
    lines.prepare(next_frame(armed))
    assert built == [Command(8, 0, 250, HostMode.ARMED)]
    line = lines.line(Command(8, 0, 250, HostMode.ARMED))   # the one expected: not rebuilt
    assert len(built) == 1 and decode(line[:-1]) == Command(8, 0, 250, HostMode.ARMED)
    braking = Command(9, 60, 250, HostMode.BRAKING)
    lines.prepare(Command(9, 0, 250, HostMode.ARMED))
    line = lines.line(braking)                             # the level changed: built now
    assert built[-1] == braking and decode(line[:-1]) == braking
    assert lines.line(braking) == line and built[-1] == braking and len(built) == 4
    assert next_frame(Command(SEQ_MODULO - 1, 5, 250, HostMode.BRAKING)).seq == 0
