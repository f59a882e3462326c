"""The vehicle's state as a consumer holds it (fusion, or any service that reads
`vehicle/motion` or `vehicle/driver`): the newest message of each key, and whether it is
fresh, stale or missing, with the reason and counters. Pure: every call takes the
current times.

The policy it serves (docs/vehicle.md, "Stale or missing vehicle state"): a decision
that needs the vehicle's state uses it only while FRESH; STALE or MISSING is a degraded
mode the consumer states (the reason in its output, a counter, a WARNING), never a
default value in its place.
"""

import enum
from dataclasses import dataclass
from typing import Any, Generic, Protocol, TypeVar

from aeb_radar_camera.common.counters import ReasonCounter
from aeb_radar_camera.common.keys import EGO_MOTION, VEHICLE_DRIVER, KeySpec
from aeb_radar_camera.common.messages.header import Header
from aeb_radar_camera.common.messages.vehicle import DriverInputs, EgoMotion


class Stamped(Protocol):
    @property
    def header(self) -> Header: ...


M = TypeVar("M", bound=Stamped)


class StateFreshness(enum.Enum):
    FRESH = "fresh"
    STALE = "stale"        # received before, nothing new for longer than the bound
    MISSING = "missing"    # nothing usable received since this consumer started


@dataclass(frozen=True)
class StateCheck:
    freshness: StateFreshness
    reason: str            # empty when fresh, else what is wrong in words, with the numbers
    age_s: float | None    # since the newest accepted sample arrived; None: none yet

    @property
    def fresh(self) -> bool:
        return self.freshness is StateFreshness.FRESH


class StateInput(Generic[M]):
    """One key's newest message, fresh for `max_age_s` after it arrived.

    A sample is accepted when its measurement stamp (`header.stamp_ns`, wall clock) is
    at most `max_stamp_age_s` old on arrival (the publisher measured it recently; None:
    no stamp check, for hosts whose wall clocks are not synchronised). A sample measured
    earlier is not taken (counted ``late``), nor one older than the newest accepted
    (``out_of_order``). A stamp further ahead than `max_stamp_age_s` is taken and
    counted (``future_stamp``: the clocks disagree).

    `counts` (a ReasonCounter): ``accepted``, ``late``, ``out_of_order``,
    ``future_stamp``, ``went_stale`` (once per gap: a newest sample that outlived its
bound, seen by a check), ``checked_stale``
    and ``checked_missing`` (every `check` that found the input not fresh).
    """

    def __init__(self, name: str, max_age_s: float,
                 max_stamp_age_s: float | None = None) -> None:
        if max_age_s <= 0:
            raise ValueError(f"{name}: max_age_s must be positive")
        if max_stamp_age_s is not None and max_stamp_age_s <= 0:
            raise ValueError(f"{name}: max_stamp_age_s must be positive (or None)")
        self.name = name
        self.max_age_ns = int(max_age_s * 1e9)
        self.max_stamp_age_ns = None if max_stamp_age_s is None else int(max_stamp_age_s * 1e9)
        self.counts = ReasonCounter()
        self._latest: M | None = None
        self._arrived_mono_ns: int | None = None
        self._stale_since_arrival: int | None = None   # the arrival whose gap was counted

    @classmethod
    def from_spec(cls, spec: KeySpec[Any], stamp_check: bool = True) -> "StateInput[M]":
        """The registry's bound for the key, for the arrival and (with `stamp_check`) the
        stamp. Raises ValueError for a key without a max age."""
        if spec.max_age_s is None:
            raise ValueError(f"key {spec.name!r} has no max age")
        return cls(spec.pattern, spec.max_age_s, spec.max_age_s if stamp_check else None)

    def observe(self, msg: M, now_mono_ns: int, now_wall_ns: int) -> bool:
        """A message arrived; True when it became the newest."""
        stamp = msg.header.stamp_ns
        if self.max_stamp_age_ns is not None:
            age = now_wall_ns - stamp
            if age > self.max_stamp_age_ns:
                self.counts.add("late")
                return False
            if -age > self.max_stamp_age_ns:
                self.counts.add("future_stamp")
        if self._latest is not None and stamp < self._latest.header.stamp_ns:
            self.counts.add("out_of_order")
            return False
        self._latest = msg
        self._arrived_mono_ns = now_mono_ns
        self.counts.add("accepted")
        return True

    def check(self, now_mono_ns: int) -> StateCheck:
        """Fresh, stale or missing at `now_mono_ns`, counted."""
        arrived = self._arrived_mono_ns
        if arrived is None:
            self.counts.add("checked_missing")
            late = self.counts.get("late")
            why = f", {late} late samples refused" if late else ""
            return StateCheck(StateFreshness.MISSING,
                              f"{self.name}: nothing received{why}", None)
        age_ns = now_mono_ns - arrived
        age_s = age_ns / 1e9
        if age_ns <= self.max_age_ns:
            return StateCheck(StateFreshness.FRESH, "", age_s)
        if self._stale_since_arrival != arrived:
            self._stale_since_arrival = arrived
            self.counts.add("went_stale")
        self.counts.add("checked_stale")
        return StateCheck(StateFreshness.STALE,
                          f"{self.name}: newest is {age_s:.3f} s old "
                          f"(bound {self.max_age_ns / 1e9:.3f} s)", age_s)

    def current(self, now_mono_ns: int) -> tuple[M | None, StateCheck]:
        """The newest message while it is fresh (else None), and the check."""
        check = self.check(now_mono_ns)
        return (self._latest if check.fresh else None), check

    @property
    def latest(self) -> M | None:
        """The newest accepted message, fresh or not (for display, never for a decision)."""
        return self._latest


class VehicleState:
    """`vehicle/motion` and `vehicle/driver` as one consumer holds them: fresh for the
    registry's max age, or for `max_age_s` (a consumer's configured bound; the same
    bound for the stamp check). Raises ValueError for a bound that is not positive."""

    def __init__(self, stamp_check: bool = True, max_age_s: float | None = None) -> None:
        if max_age_s is None:
            self.motion: StateInput[EgoMotion] = StateInput.from_spec(EGO_MOTION, stamp_check)
            self.driver: StateInput[DriverInputs] = StateInput.from_spec(VEHICLE_DRIVER,
                                                                          stamp_check)
        else:
            stamp = max_age_s if stamp_check else None
            self.motion = StateInput(EGO_MOTION.pattern, max_age_s, stamp)
            self.driver = StateInput(VEHICLE_DRIVER.pattern, max_age_s, stamp)

    def checks(self, now_mono_ns: int) -> dict[str, StateCheck]:
        """Both inputs checked, by key pattern."""
        return {i.name: i.check(now_mono_ns) for i in (self.motion, self.driver)}

    def sample(self, now_mono_ns: int) -> "VehicleSample":
        """Both inputs as a decision takes them at `now_mono_ns`: each message only while
        fresh, with its check."""
        motion, motion_check = self.motion.current(now_mono_ns)
        driver, driver_check = self.driver.current(now_mono_ns)
        return VehicleSample(motion, driver, motion_check, driver_check)

    def sample_as(self, recorded_reason: str, now_mono_ns: int) -> "VehicleSample":
        """Both inputs as a recorded decision judged them, for a re-run: an input that
        `recorded_reason` (that decision's `VehicleSample.reason`) names is not used, with
        the recorded reason; the other is used with the newest message held, whatever its
        age here. A live instance on a loaded host may have received a message later than
        the recorder did: its own verdict, not the recording's arrival times, says what it
        decided on. A reason that names neither input (fusion's "vehicle state not read"
        before its first sample) holds for both. Each input is checked (and counted) at
        `now_mono_ns` as by `sample`."""
        said = recorded_reason.split("; ") if recorded_reason else []
        if said and not any(r.startswith(f"{i.name}:") for r in said
                            for i in (self.motion, self.driver)):
            said = [f"{i.name}: {recorded_reason}" for i in (self.motion, self.driver)]
        motion = self._as_recorded(self.motion, said, now_mono_ns)
        driver = self._as_recorded(self.driver, said, now_mono_ns)
        return VehicleSample(motion[0], driver[0], motion[1], driver[1])

    @staticmethod
    def _as_recorded(state: "StateInput[Any]", said: list[str],
                     now_mono_ns: int) -> tuple[Any, StateCheck]:
        check = state.check(now_mono_ns)
        reason = next((r for r in said if r.startswith(f"{state.name}:")), None)
        if reason is not None:
            freshness = StateFreshness.MISSING if state.latest is None else StateFreshness.STALE
            return None, StateCheck(freshness, reason, check.age_s)
        if state.latest is None:
            return None, check
        return state.latest, StateCheck(StateFreshness.FRESH, "", check.age_s)


@dataclass(frozen=True)
class VehicleSample:
    """The vehicle's state for one decision: a message is None unless fresh."""

    motion: EgoMotion | None
    driver: DriverInputs | None
    motion_check: StateCheck
    driver_check: StateCheck

    @property
    def reason(self) -> str:
        """Empty when both are fresh, else what is stale or missing, in words."""
        return "; ".join(c.reason for c in (self.motion_check, self.driver_check)
                         if not c.fresh)


NOT_READ = StateCheck(StateFreshness.MISSING, "not read", None)
