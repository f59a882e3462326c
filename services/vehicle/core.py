"""The vehicle gateway's pure core: the car's CAN frames (with their receive times) in,
decoded through the DBC and the configured mapping; `vehicle/motion` and
`vehicle/driver` messages out at their rates, each only while every signal it is made
of is fresh; the gateway's status. No CAN, no Zenoh, no clock: every call takes the
current times.
"""

from statistics import fmean
from typing import Any

import cantools.database

from aeb_radar_camera.common.config.vehicle import GatewaySettings
from aeb_radar_camera.common.counters import ReasonCounter
from aeb_radar_camera.common.messages.header import Header
from aeb_radar_camera.common.messages.radar import BUS_NOT_READY, BusState
from aeb_radar_camera.common.messages.vehicle import (
    DriverInputs,
    EgoMotion,
    Gear,
    SignalHealth,
    VehicleStatus,
)
from aeb_radar_camera.services.vehicle.mapping import (
    DRIVER,
    MOTION,
    Database,
    FramePlan,
    MessagePlan,
    Plan,
    Rejected,
    Slot,
    build_plan,
    convert,
)

KEYS = {MOTION: "vehicle/motion", DRIVER: "vehicle/driver"}
# the DBC decoder's complaints about a frame (wrong length, a value it cannot represent)
DECODE_ERRORS = (cantools.database.DecodeError, ValueError, KeyError, IndexError, TypeError)
_RATE_SAMPLE_NS = 500_000_000     # frames_per_s: measured over at least this long

VehicleMessage = EgoMotion | DriverInputs


class VehicleCore:
    """One gateway. `rejected` counts what could not be used, by reason; `ignored` the
    frames that are not the gateway's business; `published` / `withheld` the messages
    by key. Raises MappingError (from build_plan) when the config does not fit the DBC."""

    def __init__(self, settings: GatewaySettings, db: Database) -> None:
        self.settings = settings
        self.plan: Plan = build_plan(db, settings)
        self.source = f"vehicle/{settings.name}"
        self.rejected = ReasonCounter()
        self.ignored = ReasonCounter()
        self.published = ReasonCounter()
        self.withheld = ReasonCounter()
        self.frames_total = 0
        self.frames_decoded = 0
        self._due: dict[str, int | None] = {m.key: None for m in self.plan.messages}
        self._seq: dict[str, int] = {}
        self._rate: tuple[int, int | None, float] = (0, None, 0.0)   # frames, at, rate

    # -- frames -------------------------------------------------------------------------

    def on_frame(self, arb_id: int, data: bytes, is_extended: bool, wall_ns: int,
                 mono_ns: int) -> None:
        """One received data frame: the mapped signals it carries are decoded and kept
        with the receive times. Never raises on bad data: counted."""
        self.frames_total += 1
        frame = self.plan.frames.get((arb_id, is_extended))
        if frame is None:
            ignored = (arb_id, is_extended) in self.plan.ignored_ids
            self.ignored.add("no_mapped_signal" if ignored else "not_in_dbc")
            return
        try:
            decoded = frame.message.decode(data, decode_choices=False, scaling=True)
        except DECODE_ERRORS:
            self.rejected.add("decode_error")
            return
        if not isinstance(decoded, dict):     # a container frame: not a chassis signal
            self.rejected.add("decode_error")
            return
        self.frames_decoded += 1
        self._take(frame, decoded, wall_ns, mono_ns)

    def _take(self, frame: FramePlan, decoded: dict[str, Any], wall: int, mono: int) -> None:
        for slot in frame.slots:
            raw = decoded.get(slot.signal)
            if raw is None:          # a multiplexed signal this frame does not carry
                continue
            try:
                slot.value = convert(slot, raw)
            except Rejected as exc:
                self.rejected.add(exc.reason)
                continue
            except (TypeError, ValueError, OverflowError):
                self.rejected.add("decode_error")
                continue
            slot.wall_ns, slot.mono_ns = wall, mono

    # -- publishing ---------------------------------------------------------------------

    def poll(self, mono_ns: int, wall_ns: int) -> list[tuple[str, VehicleMessage]]:
        """The messages due at `mono_ns`, as (key, message): each message at its rate,
        and only while every signal it is made of is fresh (else counted as withheld)."""
        out: list[tuple[str, VehicleMessage]] = []
        for m in self.plan.messages:
            due = self._due[m.key]
            if due is not None and mono_ns < due:
                continue
            # on schedule while ticks keep up; restarted from now after a long gap
            self._due[m.key] = (mono_ns + m.period_ns
                                if due is None or mono_ns - due > m.period_ns
                                else due + m.period_ns)
            slots = self._slots(m)
            if not all(s.fresh(mono_ns) for s in slots):
                self.withheld.add(KEYS[m.key])
                continue
            # the newest value's receive time: the others are younger than their bounds
            stamp = max(s.wall_ns for s in slots if s.wall_ns is not None)
            header = self._header(m.key, stamp, mono_ns)
            out.append((KEYS[m.key], self._motion(m, header) if m.key == MOTION
                        else self._driver(m, header)))
            self.published.add(KEYS[m.key])
        return out

    @staticmethod
    def _slots(m: MessagePlan) -> list[Slot]:
        return [s for f in m.fields for s in f.slots] + list(m.extra)

    def _header(self, key: str, stamp_ns: int, mono_ns: int) -> Header:
        seq = self._seq.get(key, 0)
        self._seq[key] = seq + 1
        return Header(seq=seq, source=self.source, stamp_ns=stamp_ns, pub_mono_ns=mono_ns)

    @staticmethod
    def _value(slots: tuple[Slot, ...]) -> Any:
        if len(slots) == 1:
            return slots[0].value
        return fmean(float(s.value) for s in slots if isinstance(s.value, (int, float)))

    def _motion(self, m: MessagePlan, header: Header) -> EgoMotion:
        values = {f.name: float(self._value(f.slots)) for f in m.fields}
        speed = values["speed_mps"]
        if self.plan.reverse_from_gear and m.extra[0].value is Gear.REVERSE:
            speed = -abs(speed)
        return EgoMotion(header=header, speed_mps=speed, yaw_rate_dps=values["yaw_rate_dps"])

    def _driver(self, m: MessagePlan, header: Header) -> DriverInputs:
        values: dict[str, Any] = dict.fromkeys(
            ("steering_wheel_angle_deg", "steering_wheel_rate_dps", "accelerator_pedal_pct",
             "kickdown", "brake_pedal_pressed", "brake_pressure_bar", "gear"))
        values.update({f.name: self._value(f.slots) for f in m.fields})
        return DriverInputs(header=header, **values)

    # -- status -------------------------------------------------------------------------

    def signals(self, mono_ns: int) -> tuple[SignalHealth, ...]:
        return tuple(
            SignalHealth(signal=s.ref, field=s.target, fresh=s.fresh(mono_ns),
                         age_s=None if s.mono_ns is None else (mono_ns - s.mono_ns) / 1e9)
            for s in self.plan.slots)

    def not_ready_reason(self, bus_state: BusState, mono_ns: int) -> str:
        """Empty when ready: the bus active and every mapped signal fresh. Names no
        numbers, so that it changes only when the reason does."""
        if bus_state is not BusState.ACTIVE:
            return BUS_NOT_READY[bus_state]
        never = [s.ref for s in self.plan.slots if s.mono_ns is None]
        if never:
            return "never received: " + ", ".join(dict.fromkeys(never))
        stale = [s.ref for s in self.plan.slots if not s.fresh(mono_ns)]
        if stale:
            return "stale: " + ", ".join(dict.fromkeys(stale))
        return ""

    def frames_per_s(self, mono_ns: int) -> float:
        """Frames received per second, measured between calls at least
        `_RATE_SAMPLE_NS` apart (the previous figure in between)."""
        frames, at, rate = self._rate
        if at is None:
            self._rate = (self.frames_total, mono_ns, 0.0)
        elif mono_ns - at >= _RATE_SAMPLE_NS:
            rate = (self.frames_total - frames) * 1e9 / (mono_ns - at)
            self._rate = (self.frames_total, mono_ns, rate)
        return rate

    def status(self, header: Header, bus_state: BusState, mono_ns: int, interface: str,
               channel: str, dbc: str, bus_reopens: int,
               bus_rejected: dict[str, int]) -> VehicleStatus:
        reason = self.not_ready_reason(bus_state, mono_ns)
        return VehicleStatus(
            header=header, gateway=self.settings.name, ready=not reason,
            not_ready_reason=reason, bus_state=bus_state, interface=interface,
            channel=channel, dbc=dbc, frames_per_s=self.frames_per_s(mono_ns),
            frames_total=self.frames_total, frames_decoded=self.frames_decoded,
            bus_reopens=bus_reopens, signals=self.signals(mono_ns),
            published=self.published.snapshot(), withheld=self.withheld.snapshot(),
            rejected={**{f"bus:{k}": v for k, v in bus_rejected.items()},
                      **self.rejected.snapshot()},
            ignored=self.ignored.snapshot())
