"""Zenoh access for every process: open a session from settings, and publish, subscribe,
query and declare liveliness only through the key registry.

Every sample is published with its Zenoh encoding, ``application/msgpack;aeb.<Type>``
(common/messages/schema.py), so that generic tools can tell what it carries. Payloads
that do not decode are counted (`Bus.decode_errors`, by key name) and logged with a rate
limit; they never reach a callback and never raise in Zenoh's threads.
"""

import json
import logging
import re
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, Generic, TypeVar

import msgspec
import zenoh

from aeb_radar_camera.common.clock import mono_ns
from aeb_radar_camera.common.config.base import ZenohMode, ZenohSettings
from aeb_radar_camera.common.counters import ReasonCounter
from aeb_radar_camera.common.keys import HEALTH, Congestion, KeySpec, Priority
from aeb_radar_camera.common.log import RateLimitedLog, kv
from aeb_radar_camera.common.messages import DecodeError, decode, encode
from aeb_radar_camera.common.messages.schema import zenoh_encoding

T = TypeVar("T", bound=msgspec.Struct)

_log = logging.getLogger("bus")
# a client retries its router from 100 ms, doubling up to this: a router that comes up
# late is joined within a second
CONNECT_RETRY_MAX_MS = 1000
# a wait for the router is logged after this long, then again at this interval
WAIT_LOG_FIRST_S = 0.5
WAIT_LOG_INTERVAL_S = 5.0

_PRIORITY = {
    Priority.REAL_TIME: zenoh.Priority.REAL_TIME,
    Priority.INTERACTIVE_HIGH: zenoh.Priority.INTERACTIVE_HIGH,
    Priority.INTERACTIVE_LOW: zenoh.Priority.INTERACTIVE_LOW,
    Priority.DATA_HIGH: zenoh.Priority.DATA_HIGH,
    Priority.DATA: zenoh.Priority.DATA,
    Priority.DATA_LOW: zenoh.Priority.DATA_LOW,
    Priority.BACKGROUND: zenoh.Priority.BACKGROUND,
}
_CONGESTION = {
    Congestion.BLOCK: zenoh.CongestionControl.BLOCK,
    Congestion.DROP: zenoh.CongestionControl.DROP,
}


class BusError(RuntimeError):
    """The Zenoh configuration is invalid or the session could not be opened."""


# Where in zenoh's Rust source an error was raised (" at /root/.cargo/.../tcp.rs:61."):
# the build machine's paths, nothing for a user
_RUST_SOURCE = re.compile(r"\s+at\s+\S+\.rs:\d+\.?")


def zenoh_message(exc: BaseException) -> str:
    """A zenoh error's text without the source locations of zenoh's build."""
    return _RUST_SOURCE.sub("", str(exc))


def zenoh_config(settings: ZenohSettings) -> zenoh.Config:
    """Build a zenoh.Config: file first, then our fields, then raw overrides.

    Clients block in `zenoh.open` until a router is reachable (retrying with backoff), so
    that start order does not matter. Raises BusError on an unreadable file or bad key.
    """
    try:
        if settings.config_file:
            if not Path(settings.config_file).is_file():
                raise BusError(f"zenoh config file {settings.config_file!r} not found")
            conf = zenoh.Config.from_file(settings.config_file)
        else:
            conf = zenoh.Config()
        values: dict[str, Any] = {
            "mode": settings.mode.value,
            "scouting/multicast/enabled": settings.multicast_scouting,
            "scouting/gossip/enabled": settings.gossip_scouting,
        }
        if settings.connect or not settings.config_file:
            values["connect/endpoints"] = list(settings.connect)
        if settings.listen or not settings.config_file:
            values["listen/endpoints"] = list(settings.listen)
        if settings.mode is not ZenohMode.ROUTER:
            values["connect/timeout_ms"] = -1
            values["connect/exit_on_failure"] = False
            values["connect/retry"] = {
                "period_init_ms": 100,
                "period_max_ms": CONNECT_RETRY_MAX_MS,
                "period_increase_factor": 2,
            }
        values.update(settings.overrides)
        for key, value in values.items():
            try:
                conf.insert_json5(key, json.dumps(value))
            except zenoh.ZError as exc:
                raise BusError(f"invalid zenoh configuration: {key} = {value!r}: "
                               f"{zenoh_message(exc)}") from exc
    except (zenoh.ZError, TypeError, ValueError) as exc:
        # ZError: a key, value or file zenoh refuses; TypeError/ValueError: an override
        # that is not JSON
        raise BusError(f"invalid zenoh configuration: {zenoh_message(exc)}") from exc
    return conf


def open_session(settings: ZenohSettings) -> zenoh.Session:
    """Open a session (blocks until a router is reachable for clients). Raises BusError."""
    conf = zenoh_config(settings)
    try:
        return zenoh.open(conf)
    except zenoh.ZError as exc:
        raise BusError(f"cannot open zenoh session: {zenoh_message(exc)}") from exc


def encoding(spec: KeySpec[Any]) -> zenoh.Encoding | None:
    """The Zenoh encoding of a key's samples (None for a key without a message)."""
    return None if spec.msg_type is None else zenoh.Encoding(zenoh_encoding(spec.msg_type))


class TypedPublisher(Generic[T]):
    """A declared publisher for one concrete key, with the registry's QoS and the key's
    message encoding."""

    def __init__(self, session: zenoh.Session, spec: KeySpec[T], key: str) -> None:
        self.spec = spec
        self.key = key
        self._pub = session.declare_publisher(
            key,
            encoding=encoding(spec),
            priority=_PRIORITY[spec.qos.priority],
            congestion_control=_CONGESTION[spec.qos.congestion],
            express=spec.qos.express,
        )

    def put(self, msg: T) -> None:
        self._pub.put(encode(msg))

    def put_bytes(self, payload: bytes) -> None:
        """Publish bytes as they are, with this key's QoS (for relays and benchmark
        floors: nothing checks that they decode as the key's message)."""
        self._pub.put(payload)

    def undeclare(self) -> None:
        self._pub.undeclare()


class Bus:
    """A session plus the vehicle prefix; the only way services touch Zenoh.

    Use as a context manager so that the session is closed (a callback subscriber in an
    unclosed session can hang interpreter exit).
    """

    def __init__(self, session: zenoh.Session, vehicle: str, source: str) -> None:
        self.session = session
        self.vehicle = vehicle
        self.source = source
        self.decode_errors = ReasonCounter()
        self.callback_errors = ReasonCounter()
        self._rl = RateLimitedLog(_log)
        self._seqs: dict[str, int] = {}
        self._seq_lock = threading.Lock()
        self._closed = False

    @classmethod
    def open(cls, settings: ZenohSettings, vehicle: str, source: str) -> "Bus":
        """Open a session from settings (blocks until a router answers). Raises BusError."""
        return cls(open_session(settings), vehicle, source)

    @classmethod
    def open_until_stopped(cls, settings: ZenohSettings, vehicle: str, source: str,
                           stop: threading.Event,
                           log: logging.Logger | None = None) -> "Bus | None":
        """Open a session while `stop` can still end the wait: None once `stop` is set
        before a router answered (nothing was done yet: the caller exits cleanly).

        `zenoh.open` blocks until a router is reachable and a signal handler only runs
        once it returns, so the session is opened on a helper thread while this thread
        waits on `stop`. A client's wait is logged at once with the endpoints, then every
        `WAIT_LOG_INTERVAL_S` while Zenoh keeps retrying. Raises BusError.
        """
        log = log or _log
        result: list[Bus | BaseException] = []
        done = threading.Event()
        abandoned = threading.Event()
        handover = threading.Lock()

        def opener() -> None:
            try:
                bus: Bus | BaseException = cls.open(settings, vehicle, source)
            except BaseException as exc:  # handed to the waiting thread
                bus = exc
            with handover:
                if isinstance(bus, Bus) and abandoned.is_set():
                    bus.close()  # nobody will take it
                result.append(bus)
                done.set()

        threading.Thread(target=opener, name="bus-open", daemon=True).start()
        endpoints = ",".join(settings.connect or settings.listen) or "(config file)"
        started = mono_ns()
        # a router (or a peer) waits for nobody: its open only takes zenoh's scouting delay
        says_wait = settings.mode is ZenohMode.CLIENT
        if not done.wait(WAIT_LOG_FIRST_S) and says_wait:
            log.warning(kv("waiting_for_router", endpoints=endpoints, mode=settings.mode.value,
                           retry_max_ms=CONNECT_RETRY_MAX_MS))
        next_log = started + int((WAIT_LOG_FIRST_S + WAIT_LOG_INTERVAL_S) * 1e9)
        while not done.wait(0.05):
            if stop.is_set():
                with handover:
                    if done.is_set():
                        break
                    abandoned.set()
                log.info(kv("stopped_waiting_for_router", endpoints=endpoints,
                            waited_s=round((mono_ns() - started) / 1e9, 1)))
                return None
            if says_wait and mono_ns() >= next_log:
                next_log += int(WAIT_LOG_INTERVAL_S * 1e9)
                log.warning(kv("still_waiting_for_router", endpoints=endpoints,
                               waited_s=round((mono_ns() - started) / 1e9, 1)))
        outcome = result[0]
        if isinstance(outcome, BaseException):
            raise outcome
        if stop.is_set():
            outcome.close()
            return None
        if says_wait and mono_ns() - started > int(WAIT_LOG_FIRST_S * 1e9):
            log.info(kv("router_reached", endpoints=endpoints,
                        waited_s=round((mono_ns() - started) / 1e9, 1)))
        return outcome

    def __enter__(self) -> "Bus":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.session.close()

    def next_seq(self, stream: str) -> int:
        """Sequence numbers per stream, starting at 0."""
        with self._seq_lock:
            seq = self._seqs.get(stream, 0)
            self._seqs[stream] = seq + 1
            return seq

    def key(self, spec: KeySpec[Any], **params: str) -> str:
        return spec.key(self.vehicle, **params)

    def publisher(self, spec: KeySpec[T], **params: str) -> TypedPublisher[T]:
        return TypedPublisher(self.session, spec, self.key(spec, **params))

    def subscribe(
        self,
        spec: KeySpec[T],
        callback: Callable[[T, str], None],
        **params: str,
    ) -> zenoh.Subscriber[None]:
        """Subscribe to a key (missing parameters become `*`); `callback(msg, key)` gets
        decoded messages only. Undecodable payloads are counted and logged."""
        msg_type = spec.msg_type
        if msg_type is None:
            raise ValueError(f"key {spec.name!r} carries no message")
        expr = spec.wildcard(self.vehicle, **params)

        def on_sample(sample: zenoh.Sample) -> None:
            if sample.kind != zenoh.SampleKind.PUT:
                return
            key = str(sample.key_expr)
            msg = self._decoded(spec, msg_type, sample, key)
            if msg is None:
                return
            try:
                callback(msg, key)
            except Exception as exc:  # a subscriber's bug must not end delivery to the rest
                self._callback_failed(spec.name, key, exc)

        return self.session.declare_subscriber(expr, on_sample)

    def subscribe_raw(
        self, spec: KeySpec[Any], callback: Callable[[bytes, str, int], None], **params: str,
    ) -> zenoh.Subscriber[None]:
        """Subscribe without decoding: `callback(payload, key, receipt_mono_ns)`.

        For shells that decode off Zenoh's thread (e.g. JPEG frames) or time the receipt.
        """
        return self._declare_raw(spec.wildcard(self.vehicle, **params), spec.name,
                                 lambda s, key, t: callback(s.payload.to_bytes(), key, t))

    def subscribe_expr(
        self, key_expr: str, callback: Callable[[bytes, str, str, int], None],
    ) -> zenoh.Subscriber[None]:
        """Every sample on a key expression, whatever key or message it is:
        `callback(payload, key, encoding, receipt_mono_ns)` (for tools that watch any key:
        `aeb echo`, `aeb hz`). `key_expr` is absolute (``aeb/<vehicle>/...``)."""
        return self._declare_raw(key_expr, "expr", lambda s, key, t: callback(
            s.payload.to_bytes(), key, str(s.encoding), t))

    def _declare_raw(self, expr: str, name: str,
                     deliver: Callable[[zenoh.Sample, str, int], None]) -> zenoh.Subscriber[None]:
        """`deliver(sample, key, receipt_mono_ns)` for every PUT; a failure is counted in
        `callback_errors` under `name` and logged."""

        def on_sample(sample: zenoh.Sample) -> None:
            if sample.kind != zenoh.SampleKind.PUT:
                return
            t = mono_ns()
            key = str(sample.key_expr)
            try:
                deliver(sample, key, t)
            except Exception as exc:  # a subscriber's bug must not end delivery to the rest
                self._callback_failed(name, key, exc)

        return self.session.declare_subscriber(expr, on_sample)

    def subscribe_queued(
        self, spec: KeySpec[Any], capacity: int, **params: str,
    ) -> zenoh.Subscriber[zenoh.Handler[zenoh.Sample]]:
        """Subscribe into a queue that Zenoh fills without running any Python: no thread
        takes this process's GIL when a sample arrives (for instruments that must not
        delay the threads they share a process with). Drain with `drain_queued`.

        Zenoh's receive thread waits when the queue is full: size `capacity` for
        everything that can arrive between two drains."""
        if capacity <= 0:
            raise ValueError(f"capacity must be positive, got {capacity}")
        return self.session.declare_subscriber(spec.wildcard(self.vehicle, **params),
                                               zenoh.handlers.FifoChannel(capacity))

    def drain_queued(self, spec: KeySpec[T],
                     sub: zenoh.Subscriber[zenoh.Handler[zenoh.Sample]]) -> list[tuple[T, str]]:
        """Everything queued so far by `subscribe_queued`, decoded, in arrival order
        (before `sub` is undeclared: the queue goes with it). Undecodable payloads are
        counted in `decode_errors` and left out."""
        msg_type = spec.msg_type
        if msg_type is None:
            raise ValueError(f"key {spec.name!r} carries no message")
        out: list[tuple[T, str]] = []
        while (sample := sub.try_recv()) is not None:
            if sample.kind != zenoh.SampleKind.PUT:
                continue
            key = str(sample.key_expr)
            msg = self._decoded(spec, msg_type, sample, key)
            if msg is not None:
                out.append((msg, key))
        return out

    def _callback_failed(self, name: str, key: str, exc: Exception) -> None:
        self.callback_errors.add(name)
        self._rl.error(f"cb:{name}", "callback_failed", key=key, error=repr(exc))
        _log.debug("callback traceback", exc_info=True)

    def _decoded(self, spec: KeySpec[Any], msg_type: type[T], sample: zenoh.Sample,
                 key: str) -> T | None:
        """The sample's message; None, counted and logged, when it does not decode."""
        try:
            return decode(sample.payload.to_bytes(), msg_type)
        except DecodeError as exc:
            self.decode_errors.add(spec.name)
            self._rl.warning(f"decode:{spec.name}", "undecodable_payload", key=key, error=exc)
            return None

    def declare_queryable(
        self, spec: KeySpec[T], reply: Callable[[], T], **params: str
    ) -> zenoh.Queryable[None]:
        """Answer queries on one concrete key with `reply()`, encoded. A `reply` that
        raises is counted in `callback_errors` and answered with an error reply."""
        key = self.key(spec, **params)
        reply_encoding = encoding(spec)

        def on_query(query: zenoh.Query) -> None:
            try:
                payload = encode(reply())
            except Exception as exc:  # the querier gets an error reply, not a timeout
                self.callback_errors.add(spec.name)
                self._rl.error(f"query:{spec.name}", "query_reply_failed", key=key,
                               error=repr(exc))
                query.reply_err(f"{type(exc).__name__}: {exc}")
                return
            query.reply(key, payload, encoding=reply_encoding)

        return self.session.declare_queryable(key, on_query)

    def query(self, spec: KeySpec[T], timeout_s: float = 2.0,
              **params: str) -> list[tuple[T, str]]:
        """Query a key (missing parameters become `*`); blocks until every replier
        answered or `timeout_s`. Returns decoded replies with their keys; error replies
        and undecodable payloads are counted in `decode_errors` and left out."""
        msg_type = spec.msg_type
        if msg_type is None:
            raise ValueError(f"key {spec.name!r} carries no message")
        out: list[tuple[T, str]] = []
        for reply in self.session.get(spec.wildcard(self.vehicle, **params), timeout=timeout_s):
            sample = reply.ok
            try:
                if sample is None:
                    err = reply.err
                    raise DecodeError(
                        f"error reply: {err.payload.to_string() if err is not None else '?'}")
                out.append((decode(sample.payload.to_bytes(), msg_type), str(sample.key_expr)))
            except DecodeError as exc:
                self.decode_errors.add(spec.name)
                self._rl.warning(f"decode:{spec.name}", "bad_query_reply", error=exc)
        return out

    def declare_health(self, service: str, instance: str) -> zenoh.LivelinessToken:
        """Declare this process alive: `health/<service>/<instance>`. Declare it last, once
        the service is ready, so that seeing the token means the service is serving."""
        return self.session.liveliness().declare_token(
            self.key(HEALTH, service=service, instance=instance)
        )

    def subscribe_health(
        self, callback: Callable[[str, str, bool], None], history: bool = True
    ) -> zenoh.Subscriber[None]:
        """`callback(service, instance, alive)` for every token appearing or vanishing."""

        def on_sample(sample: zenoh.Sample) -> None:
            params = HEALTH.match(str(sample.key_expr), self.vehicle)
            if params is not None:
                callback(params["service"], params["instance"],
                         sample.kind == zenoh.SampleKind.PUT)

        return self.session.liveliness().declare_subscriber(
            HEALTH.wildcard(self.vehicle), on_sample, history=history
        )
