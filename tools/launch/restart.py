"""When and how soon to restart a service that exited: the pure policy of `aeb up`.

No clocks, no processes: the supervisor passes in how the process ended and how long it
ran, and gets back whether to start it again and after what delay.
"""

import enum
import signal
from dataclasses import dataclass, replace
from typing import Annotated

import msgspec

# A process that exits with this code rejected its configuration: restarting it cannot
# help (common.config.loader exits 2 on an invalid config, argparse on bad arguments).
CONFIG_ERROR_EXIT = 2


class RestartMode(enum.Enum):
    ALWAYS = "always"          # restart whatever the exit (also a clean exit 0)
    ON_FAILURE = "on-failure"  # restart after a non-zero exit or a signal
    NEVER = "never"


class Backoff(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """Delay before restart k (k from 0) is `initial_s * factor**k`, at most `max_s`.

    A run that lasted `stable_after_s` or longer resets k to 0. After `give_up_after`
    failures in a row that each ran less than `stable_after_s`, the service is left down
    (0: never give up, the default on a vehicle).
    """

    initial_s: Annotated[float, msgspec.Meta(ge=0)] = 0.5
    max_s: Annotated[float, msgspec.Meta(ge=0)] = 10.0
    factor: Annotated[float, msgspec.Meta(ge=1)] = 2.0
    stable_after_s: Annotated[float, msgspec.Meta(gt=0)] = 30.0
    give_up_after: Annotated[int, msgspec.Meta(ge=0)] = 0

    def __post_init__(self) -> None:
        if self.max_s < self.initial_s:
            raise ValueError(f"max_s ({self.max_s}) is below initial_s ({self.initial_s})")


@dataclass(frozen=True)
class RestartState:
    """What the policy remembers about one service between exits."""

    quick_exits: int = 0   # exits in a row after runs shorter than stable_after_s
    restarts: int = 0      # restarts so far (for display)


@dataclass(frozen=True)
class RestartDecision:
    restart: bool
    delay_s: float
    reason: str


def describe_exit(returncode: int) -> str:
    """'exit 1' or 'killed by SIGSEGV' (Popen reports a signal as -signum)."""
    if returncode >= 0:
        return f"exit {returncode}"
    try:
        return f"killed by {signal.Signals(-returncode).name}"
    except ValueError:
        return f"killed by signal {-returncode}"


def on_exit(
    mode: RestartMode,
    backoff: Backoff,
    state: RestartState,
    returncode: int,
    ran_s: float,
    stopping: bool = False,
) -> tuple[RestartDecision, RestartState]:
    """Decide what to do about a process that ended with `returncode` after `ran_s` s.

    The delay grows with every quick exit in a row, failure or not, so that a service
    that exits at once (even with 0 under `always`) cannot spin.
    """
    how = describe_exit(returncode)
    if stopping:
        return RestartDecision(False, 0.0, f"{how} while stopping"), state
    if returncode == CONFIG_ERROR_EXIT:
        return RestartDecision(False, 0.0, f"{how}: configuration rejected, not restarted"), state
    if mode is RestartMode.NEVER or (mode is RestartMode.ON_FAILURE and returncode == 0):
        return RestartDecision(False, 0.0, f"{how}, restart={mode.value}: not restarted"), state
    streak = state.quick_exits + 1 if ran_s < backoff.stable_after_s else 0
    if backoff.give_up_after and streak >= backoff.give_up_after:
        return (
            RestartDecision(False, 0.0, f"{how}: gave up after {streak} quick exits in a row"),
            replace(state, quick_exits=streak),
        )
    delay = min(backoff.initial_s * backoff.factor ** max(streak - 1, 0), backoff.max_s)
    return (
        RestartDecision(True, delay, f"{how}: restarting in {delay:.1f} s"),
        RestartState(quick_exits=streak, restarts=state.restarts + 1),
    )
