"""The pure restart policy of `aeb up`."""

import signal

import pytest

from aeb_radar_camera.tools.launch.restart import (
    Backoff,
    RestartMode,
    RestartState,
    describe_exit,
    on_exit,
)

B = Backoff(initial_s=0.5, max_s=4.0, factor=2.0, stable_after_s=10.0)


def run_exits(mode, exits, backoff=B):
    """Feed (returncode, ran_s) pairs; return the decisions."""
    state = RestartState()
    out = []
    for code, ran in exits:
        decision, state = on_exit(mode, backoff, state, code, ran)
        out.append(decision)
    return out, state


def test_quick_crashes_back_off_exponentially_up_to_the_cap():
    decisions, state = run_exits(RestartMode.ON_FAILURE, [(1, 0.1)] * 6)
    assert all(d.restart for d in decisions)
    assert [d.delay_s for d in decisions] == [0.5, 1.0, 2.0, 4.0, 4.0, 4.0]
    assert state.restarts == 6


def test_a_stable_run_resets_the_backoff():
    decisions, _ = run_exits(RestartMode.ON_FAILURE, [(1, 0.1), (1, 0.1), (1, 0.1), (1, 60.0),
                                                      (1, 0.1)])
    assert [d.delay_s for d in decisions] == [0.5, 1.0, 2.0, 0.5, 0.5]


def test_a_signal_is_a_failure_and_is_named():
    decision, _ = on_exit(RestartMode.ON_FAILURE, B, RestartState(), -signal.SIGSEGV, 3.0)
    assert decision.restart
    assert "SIGSEGV" in decision.reason
    assert describe_exit(-signal.SIGKILL) == "killed by SIGKILL"
    assert describe_exit(3) == "exit 3"


def test_clean_exit_restarts_only_under_always_and_still_backs_off():
    d, _ = on_exit(RestartMode.ON_FAILURE, B, RestartState(), 0, 1.0)
    assert not d.restart and "not restarted" in d.reason
    decisions, _ = run_exits(RestartMode.ALWAYS, [(0, 0.1)] * 3)
    assert [d.delay_s for d in decisions] == [0.5, 1.0, 2.0]


@pytest.mark.parametrize("mode", list(RestartMode))
def test_a_rejected_configuration_is_never_restarted(mode):
    d, _ = on_exit(mode, B, RestartState(), 2, 0.1)
    assert not d.restart
    assert "configuration rejected" in d.reason


def test_never_means_never_and_stopping_wins():
    d, _ = on_exit(RestartMode.NEVER, B, RestartState(), 1, 0.1)
    assert not d.restart
    d, _ = on_exit(RestartMode.ALWAYS, B, RestartState(), -signal.SIGTERM, 100.0, stopping=True)
    assert not d.restart and "while stopping" in d.reason


def test_give_up_after_quick_exits_in_a_row():
    b = Backoff(initial_s=0.1, max_s=1.0, stable_after_s=10.0, give_up_after=3)
    decisions, _ = run_exits(RestartMode.ALWAYS, [(1, 0.1)] * 3, b)
    assert [d.restart for d in decisions] == [True, True, False]
    assert "gave up after 3" in decisions[-1].reason
    # A stable run in between starts the count again.
    decisions, _ = run_exits(RestartMode.ALWAYS, [(1, 0.1), (1, 0.1), (1, 50.0), (1, 0.1)], b)
    assert all(d.restart for d in decisions)


def test_backoff_rejects_a_cap_below_the_start():
    with pytest.raises(ValueError, match="max_s"):
        Backoff(initial_s=5.0, max_s=1.0)
