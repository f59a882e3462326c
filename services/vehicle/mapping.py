"""The gateway's configuration resolved against the car's DBC: which frames carry which
mapped signals, and how each signal's decoded value becomes a message field. Pure
(the DBC is already loaded); every name the config gives is checked here, so that a
wrong one fails at start (`MappingError`), not on the road."""

import math
from dataclasses import dataclass, field
from typing import Any

import cantools.database

from aeb_radar_camera.common.config.vehicle import (
    FlagMap,
    GatewaySettings,
    GearMap,
    ValueMap,
    signal_names,
)
from aeb_radar_camera.common.messages.vehicle import Gear

Database = cantools.database.can.Database
DbcMessage = cantools.database.can.Message
DbcSignal = cantools.database.can.Signal

MOTION = "motion"
DRIVER = "driver"


class MappingError(ValueError):
    """A mapping names a signal the DBC does not have (or more than one), a gear value
    it does not know, or maps a signal that cannot be used that way."""


@dataclass
class Slot:
    """One DBC signal feeding one message field, with its newest accepted value.

    `kind`: ``value`` (scaled number), ``flag`` (above a threshold) or ``gear``."""

    target: str                      # the field it feeds: "motion.speed_mps", "driver.gear"
    ref: str                         # "Message.Signal"
    signal: str                      # the signal's name inside its message
    kind: str
    max_age_ns: int
    scale: float = 1.0
    offset: float = 0.0
    low: float | None = None
    high: float | None = None
    above: float = 0.5
    gears: dict[int, Gear] = field(default_factory=dict)
    raw_scale: float = 1.0           # the DBC's own conversion, undone for gear codes
    raw_offset: float = 0.0
    value: float | bool | Gear | None = None
    wall_ns: int | None = None
    mono_ns: int | None = None

    def fresh(self, mono_ns: int) -> bool:
        return self.mono_ns is not None and mono_ns - self.mono_ns <= self.max_age_ns


@dataclass(frozen=True)
class FieldPlan:
    """A message field and the slots it is made of (several: their mean)."""

    name: str
    slots: tuple[Slot, ...]


@dataclass(frozen=True)
class MessagePlan:
    key: str                          # "motion" or "driver"
    period_ns: int
    fields: tuple[FieldPlan, ...]
    extra: tuple[Slot, ...] = ()      # slots a field depends on (motion: the gear)


@dataclass(frozen=True)
class FramePlan:
    """One DBC message that carries at least one mapped signal."""

    message: DbcMessage
    slots: tuple[Slot, ...]


@dataclass(frozen=True)
class Plan:
    frames: dict[tuple[int, bool], FramePlan]     # by (arbitration ID, extended)
    messages: tuple[MessagePlan, ...]
    reverse_from_gear: bool
    ignored_ids: frozenset[tuple[int, bool]]      # in the DBC, no mapped signal

    @property
    def slots(self) -> tuple[Slot, ...]:
        """Every slot once, in message and field order."""
        seen: dict[int, Slot] = {}
        for m in self.messages:
            for f in m.fields:
                for s in f.slots:
                    seen.setdefault(id(s), s)
            for s in m.extra:
                seen.setdefault(id(s), s)
        return tuple(seen.values())


def _find(db: Database, name: str, where: str) -> tuple[DbcMessage, DbcSignal]:
    msg_name, dot, sig_name = name.rpartition(".")
    if dot:
        try:
            message = db.get_message_by_name(msg_name)
        except KeyError:
            raise MappingError(f"{where}: the DBC has no message {msg_name!r}") from None
        try:
            return message, message.get_signal_by_name(sig_name)
        except KeyError:
            raise MappingError(f"{where}: message {msg_name} has no signal {sig_name!r} "
                               f"(it has: {', '.join(s.name for s in message.signals)})"
                               ) from None
    found = [(m, s) for m in db.messages for s in m.signals if s.name == name]
    if not found:
        raise MappingError(f"{where}: the DBC has no signal {name!r}")
    if len(found) > 1:
        raise MappingError(f"{where}: signal {name!r} is in several messages "
                           f"({', '.join(m.name for m, _ in found)}): write Message.Signal")
    return found[0]


def _gear_codes(gear: GearMap, sig: DbcSignal, where: str) -> dict[int, Gear]:
    names = {str(v): int(raw) for raw, v in (sig.choices or {}).items()}
    codes: dict[int, Gear] = {}
    for key, value in gear.values.items():
        try:
            raw = int(key, 0)
        except ValueError:
            if key not in names:
                known = ", ".join(sorted(names)) or "none: use the raw numbers"
                raise MappingError(f"{where}.values: {key!r} is neither a number nor one of "
                                   f"the DBC's names for {sig.name} ({known})") from None
            raw = names[key]
        codes[raw] = Gear(value)
    return codes


class _Builder:
    def __init__(self, db: Database, settings: GatewaySettings) -> None:
        self.db = db
        self.settings = settings
        self.by_frame: dict[tuple[int, bool], tuple[DbcMessage, list[Slot]]] = {}

    def slots(self, table: str, name: str, mapping: ValueMap | FlagMap | GearMap
              ) -> tuple[Slot, ...]:
        where = f"gateway.{table}.{name}"
        age = mapping.max_age_s or self.settings.signal_max_age_s
        out = []
        for ref in signal_names(mapping.signal):
            message, sig = _find(self.db, ref, where)
            full = f"{message.name}.{sig.name}"
            slot = Slot(target=f"{table}.{self.field_name(table, name)}", ref=full,
                        signal=sig.name, kind="value", max_age_ns=int(age * 1e9),
                        raw_scale=float(sig.scale), raw_offset=float(sig.offset))
            if isinstance(mapping, ValueMap):
                slot.scale, slot.offset = mapping.scale, mapping.offset
                slot.low, slot.high = mapping.min, mapping.max
            elif isinstance(mapping, FlagMap):
                slot.kind, slot.above = "flag", mapping.above
            else:
                slot.kind, slot.gears = "gear", _gear_codes(mapping, sig, where)
            frame = (message.frame_id, bool(message.is_extended_frame))
            self.by_frame.setdefault(frame, (message, []))[1].append(slot)
            out.append(slot)
        return tuple(out)

    @staticmethod
    def field_name(table: str, name: str) -> str:
        if table == MOTION:
            return {"speed": "speed_mps", "yaw_rate": "yaw_rate_dps"}[name]
        return name


def build_plan(db: Database, settings: GatewaySettings) -> Plan:
    """The plan of `settings` on `db`. Raises MappingError naming the setting."""
    b = _Builder(db, settings)
    messages: list[MessagePlan] = []
    driver = settings.driver
    wanted = driver.mapped() if driver.publish else {}
    if settings.motion.reverse_from_gear and driver.gear is not None:
        wanted.setdefault("gear", driver.gear)
    driver_fields = {name: b.slots(DRIVER, name, m) for name, m in wanted.items()}
    if settings.motion.publish:
        motion = settings.motion
        assert motion.speed is not None and motion.yaw_rate is not None   # validated
        fields = (FieldPlan("speed_mps", b.slots(MOTION, "speed", motion.speed)),
                  FieldPlan("yaw_rate_dps", b.slots(MOTION, "yaw_rate", motion.yaw_rate)))
        extra = driver_fields["gear"] if motion.reverse_from_gear else ()
        messages.append(MessagePlan(MOTION, int(1e9 / motion.rate_hz), fields, extra))
    if driver.publish:
        messages.append(MessagePlan(
            DRIVER, int(1e9 / driver.rate_hz),
            tuple(FieldPlan(name, slots) for name, slots in driver_fields.items())))
    frames = {k: FramePlan(m, tuple(slots)) for k, (m, slots) in b.by_frame.items()}
    ignored = frozenset((m.frame_id, bool(m.is_extended_frame)) for m in db.messages
                        if (m.frame_id, bool(m.is_extended_frame)) not in frames)
    return Plan(frames, tuple(messages), settings.motion.reverse_from_gear, ignored)


class Rejected(ValueError):
    """A decoded value that cannot be taken; `reason` is its counter's name."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


def convert(slot: Slot, value: Any) -> float | bool | Gear:
    """A signal's decoded (physical) value as the slot's field value. Raises Rejected."""
    name = slot.target.split(".", 1)[1]
    number = float(value)
    if not math.isfinite(number):
        raise Rejected(f"not_finite:{name}")
    if slot.kind == "flag":
        return number > slot.above
    if slot.kind == "gear":
        raw = round((number - slot.raw_offset) / slot.raw_scale)
        gear = slot.gears.get(raw)
        if gear is None:
            raise Rejected(f"unmapped_gear:{raw}")
        return gear
    out = slot.scale * number + slot.offset
    if (slot.low is not None and out < slot.low) or (slot.high is not None and out > slot.high):
        raise Rejected(f"out_of_range:{name}")
    return out
