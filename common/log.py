"""Structured logging (one `event key=value` line per record) with rate limits for repeats."""

import argparse
import logging
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

from aeb_radar_camera.common.config.base import LogLevel

_FORMAT = "%(asctime)s.%(msecs)03d %(levelname)s %(name)s %(message)s"
LOG_LEVELS = tuple(level.value for level in LogLevel)


def log_level(text: str) -> str:
    """An argparse type: a level name in any case, returned upper case. Raises
    argparse.ArgumentTypeError naming the levels (argparse then exits with code 2)."""
    level = text.upper()
    if level not in LOG_LEVELS:
        raise argparse.ArgumentTypeError(
            f"invalid level {text!r}; choose one of {', '.join(LOG_LEVELS)}")
    return level


def add_log_level(parser: argparse.ArgumentParser, default: str | None = None) -> None:
    """`--log-level LEVEL`, the same on every command. `default` None: the command's own
    (a service's config file, `[log] level`)."""
    fallback = default or "the config's [log] level"
    parser.add_argument("--log-level", type=log_level, default=default, metavar="LEVEL",
                        help=f"{' | '.join(LOG_LEVELS)} (default: {fallback})")


class _CurrentStderrHandler(logging.StreamHandler):
    """Writes to whatever `sys.stderr` is at the time of the record, not the stream of the
    day it was set up: a handler holding an old stream (a test harness's closed capture, a
    redirected stderr) turns every later record into a "Logging error"."""

    @property
    def stream(self) -> Any:
        return sys.stderr

    @stream.setter
    def stream(self, value: Any) -> None:
        pass


def setup_logging(service: str, level: str = "INFO") -> logging.Logger:
    """Configure the root handler once (stderr) and return the service's logger."""
    root = logging.getLogger()
    if not any(getattr(h, "_aeb", False) for h in root.handlers):
        handler = _CurrentStderrHandler()
        handler.setFormatter(logging.Formatter(_FORMAT, datefmt="%H:%M:%S"))
        handler._aeb = True  # type: ignore[attr-defined]
        root.addHandler(handler)
    root.setLevel(level)
    return logging.getLogger(service)


def kv(event: str, **fields: Any) -> str:
    """`event key=value ...`, values with spaces quoted, so that lines stay greppable."""
    parts = [event]
    for k, v in fields.items():
        s = f"{v:.6g}" if isinstance(v, float) else str(v)
        if not s or any(c.isspace() for c in s):
            s = repr(s)
        parts.append(f"{k}={s}")
    return " ".join(parts)


class RateLimitedLog:
    """Logs a repeated event at most once per `interval_s` per key, counting what it held back.

    Thread-safe: I/O shells call it from Zenoh callbacks and timers.
    """

    def __init__(
        self,
        logger: logging.Logger,
        interval_s: float = 5.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._logger = logger
        self._interval_s = interval_s
        self._clock = clock
        self._last: dict[str, float] = {}
        self._held: dict[str, int] = {}
        self._lock = threading.Lock()

    def log(self, level: int, key: str, event: str, /, **fields: Any) -> bool:
        """Returns True when the line was written."""
        now = self._clock()
        with self._lock:
            last = self._last.get(key)
            if last is not None and now - last < self._interval_s:
                self._held[key] = self._held.get(key, 0) + 1
                return False
            self._last[key] = now
            held = self._held.pop(key, 0)
        if held:
            fields["repeated"] = held
        self._logger.log(level, kv(event, **fields))
        return True

    def warning(self, key: str, event: str, /, **fields: Any) -> bool:
        return self.log(logging.WARNING, key, event, **fields)

    def error(self, key: str, event: str, /, **fields: Any) -> bool:
        return self.log(logging.ERROR, key, event, **fields)
