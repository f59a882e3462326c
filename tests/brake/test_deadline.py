"""A command publisher that stops (SIGKILL, and separately SIGSTOP) leads to
FAILSAFE within the deadline plus one timer period, in every one of 50 trials of each
kind; each fail-safe policy does what docs/brake.md says on the serial line.

Timing is taken from the service's own BrakeStatus stamps (monotonic, this host):
FAILSAFE entry (`state_since_mono_ns`) minus the receipt of the last valid command
(`last_cmd_rx_mono_ns`). The serial line (what the simulated actuator read) is checked
against the same instants: no line of the fail-safe before entry, and the policy's levels
after it.
"""

import signal
import statistics
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import pytest

from aeb_radar_camera.common.messages import BrakeState, BrakeStatus
from aeb_radar_camera.services.brake.protocol import HostMode
from aeb_radar_camera.tools.sim.actuator import Received
from tests.brake.rig import BrakeRig, brake_rig
from tests.support import ServiceProcess, wait_for

pytestmark = pytest.mark.slow

TRIALS = 50
BRAKE_LEVEL = 60.0
HOLD_S = 0.4
STOP_LEVEL = 30.0
MS = 1_000_000
REPORTED_LATE_MS = 10.0   # printed, not asserted: the timer's wake-up latency


@dataclass
class Trial:
    how: str
    level: float
    status: BrakeStatus       # the first FAILSAFE status
    entry_ns: int             # FAILSAFE entry (service clock)
    last_rx_ns: int           # receipt of the last valid command (service clock)
    last_pub_ns: int          # that command's publish time (publisher clock, same host)
    line_ns: int              # the first FAILSAFE line read by the actuator

    @property
    def detect_ms(self) -> float:
        return (self.entry_ns - self.last_rx_ns) / MS


def _published_after(t_ns: int) -> Callable[[BrakeStatus], bool]:
    return lambda s: s.header.pub_mono_ns > t_ns


def _spawn(rig: BrakeRig, level: float) -> tuple[ServiceProcess, int]:
    start = len(rig.status)
    pub = rig.publisher(level=level)
    return pub, rig.wait_live(start, level)


def _trial(rig: BrakeRig, pub: ServiceProcess, how: str, level: float, live_at: int) -> Trial:
    """Stop the publisher (kill or pause) once the service follows it, and time it."""
    rig.wait_status(lambda s: s.state in (BrakeState.ARMED, BrakeState.BRAKING), live_at)
    start = len(rig.status)
    pub.signal(signal.SIGKILL if how == "kill" else signal.SIGSTOP)
    _, fs = rig.wait_status(lambda s: s.state is BrakeState.FAILSAFE, start, 10, "FAILSAFE")
    entry, last_rx = fs.state_since_mono_ns, fs.last_cmd_rx_mono_ns
    sent = [m for _, m in rig.commands.items
            if m.header.seq == fs.last_cmd_seq and m.header.pub_mono_ns <= last_rx]
    assert sent, "the last accepted command was never published"

    def failsafe_lines() -> list[Received]:
        return [r for r in rig.sim.commands_since(entry) if r.cmd.mode is HostMode.FAILSAFE]

    # read by the simulated actuator in this process: on a loaded host its thread may run
    # later than the brake's next status arrives here
    wait_for(lambda: bool(failsafe_lines()), 10, 0.01, "FAILSAFE on the actuator's line")
    lines = failsafe_lines()
    return Trial(how, level, fs, entry, last_rx, sent[-1].header.pub_mono_ns, lines[0].t_ns)


def _check_timing(rig: BrakeRig, t: Trial) -> None:
    # The bound: the deadline plus one timer period. The timer sleeps until the deadline
    # itself, so entry is usually within a millisecond of it (see _report), but a loaded
    # 2-core machine can wake it tens of ms late: the period is the guarantee.
    bound = rig.deadline_ms + rig.period_ms
    assert rig.deadline_ms <= t.detect_ms <= bound, (
        f"{t.how}: FAILSAFE {t.detect_ms:.1f} ms after the last command (bound {bound} ms)")
    assert t.last_rx_ns >= t.last_pub_ns
    assert t.line_ns >= t.entry_ns
    # the line before entry still followed the stream: FAILSAFE was not early
    before = [r for r in rig.sim.commands_since(t.last_rx_ns) if r.t_ns < t.entry_ns]
    assert before and before[-1].cmd.mode is not HostMode.FAILSAFE, before[-3:]


def _failsafe_levels(rig: BrakeRig, t: Trial, until_ns: int) -> list[tuple[int, int]]:
    return [(r.t_ns, r.cmd.level_pct) for r in rig.sim.commands_since(t.entry_ns)
            if r.t_ns < until_ns]


def _report(name: str, trials: list[Trial], deadline_ms: float) -> None:
    d = sorted(t.detect_ms for t in trials)
    e2e = sorted((t.line_ns - t.last_pub_ns) / MS for t in trials)
    late = sum(1 for t in trials if t.detect_ms > deadline_ms + REPORTED_LATE_MS)
    print(f"\n{name}: {len(d)} trials; last command -> FAILSAFE (service) "
          f"min {d[0]:.1f} / median {statistics.median(d):.1f} / max {d[-1]:.1f} ms "
          f"({late} more than {REPORTED_LATE_MS:.0f} ms after the deadline); "
          f"last publish -> FAILSAFE line read by the actuator: median "
          f"{statistics.median(e2e):.1f} / max {e2e[-1]:.1f} ms")


# ---- policy `hold` (the default): 50 kills and 50 pauses ---------------------------------

@pytest.fixture(scope="module")
def hold_rig(tmp_path_factory: pytest.TempPathFactory) -> Iterator[BrakeRig]:
    with brake_rig(tmp_path_factory.mktemp("hold"), policy="hold", failsafe_hold_s=HOLD_S,
                   min_brake_hold_ms=100.0) as rig:
        yield rig


def _check_hold(rig: BrakeRig, t: Trial) -> None:
    """Applied brake: never less than the level until the hold time has passed; idle:
    never any brake."""
    if t.level > 0:
        held = _failsafe_levels(rig, t, t.entry_ns + round(HOLD_S * 1e9))
        assert held and min(level for _, level in held) >= t.level, held
    else:
        rig.wait_status(_published_after(t.entry_ns + 100 * MS))
        assert {level for _, level in _failsafe_levels(rig, t, t.entry_ns + 100 * MS)} == {0}


def test_killed_publisher_leads_to_failsafe_in_every_trial(hold_rig):
    trials: list[Trial] = []
    levels = [BRAKE_LEVEL if i % 5 == 4 else 0.0 for i in range(TRIALS)]
    pub, live_at = _spawn(hold_rig, levels[0])
    for i, level in enumerate(levels):
        trial = _trial(hold_rig, pub, "kill", level, live_at)
        pub.stop()
        _check_timing(hold_rig, trial)
        _check_hold(hold_rig, trial)
        trials.append(trial)
        if i + 1 < TRIALS:
            pub, live_at = _spawn(hold_rig, levels[i + 1])
    _report("SIGKILL, policy hold", trials, hold_rig.deadline_ms)
    assert len(trials) == TRIALS


def test_paused_publisher_leads_to_failsafe_in_every_trial(hold_rig):
    trials: list[Trial] = []
    for level, n in ((0.0, TRIALS - 10), (BRAKE_LEVEL, 10)):
        pub, live_at = _spawn(hold_rig, level)
        try:
            for _ in range(n):
                trial = _trial(hold_rig, pub, "stop", level, live_at)
                _check_timing(hold_rig, trial)
                _check_hold(hold_rig, trial)
                trials.append(trial)
                start = len(hold_rig.status)
                pub.signal(signal.SIGCONT)   # the same stream resumes: FAILSAFE must end
                live_at = hold_rig.wait_live(start, level)
        finally:
            pub.signal(signal.SIGCONT)
            pub.stop()
    _report("SIGSTOP, policy hold", trials, hold_rig.deadline_ms)
    assert len(trials) == TRIALS


# ---- policies `stop` and `release`: fewer trials, the same checks ---------------------------

@pytest.mark.parametrize("policy", ["stop", "release"])
def test_other_policies_on_the_line(tmp_path_factory, policy):
    with brake_rig(tmp_path_factory.mktemp(policy), policy=policy,
                   failsafe_stop_level_pct=STOP_LEVEL, min_brake_hold_ms=100.0) as rig:
        trials: list[Trial] = []
        for how in ("kill", "stop"):
            for level in (0.0, BRAKE_LEVEL, 0.0):
                pub, live_at = _spawn(rig, level)
                try:
                    t = _trial(rig, pub, how, level, live_at)
                    _check_timing(rig, t)
                    trials.append(t)
                    # FAILSAFE for a while (nothing comes back during 300 ms)
                    after = t.entry_ns + 300 * MS
                    rig.wait_status(_published_after(after))
                    levels = {lv for _, lv in _failsafe_levels(rig, t, after)}
                    if policy == "stop":
                        assert levels == {int(max(STOP_LEVEL, level))}, levels
                    else:
                        assert levels == {0}, levels
                    if how == "stop":
                        start = len(rig.status)
                        pub.signal(signal.SIGCONT)
                        rig.wait_live(start, level)   # three valid commands: following again
                finally:
                    pub.signal(signal.SIGCONT)
                    pub.stop()
        _report(f"policy {policy}", trials, rig.deadline_ms)
