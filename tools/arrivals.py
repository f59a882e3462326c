"""What arrives from other threads (bus messages, CAN frames, simulator events), in order,
with the one wait for the first that matches: the tests, the fault harness and the
simulated CAN links all wait with it instead of sleeping."""

import threading
import time
from collections.abc import Callable
from typing import Generic, TypeVar

T = TypeVar("T")


class Arrivals(Generic[T]):
    """Thread-safe. A position counts every item ever added (the first is 0), so that
    positions stay valid when a bounded history (`keep`) drops its older half."""

    def __init__(self, keep: int | None = None) -> None:
        self._cond = threading.Condition()
        self._items: list[T] = []
        self._dropped = 0
        self._keep = keep

    def add(self, item: T) -> None:
        with self._cond:
            self._items.append(item)
            if self._keep is not None and len(self._items) > self._keep:
                n = self._keep // 2
                del self._items[:n]
                self._dropped += n
            self._cond.notify_all()

    def __len__(self) -> int:
        """Items added so far: the position of the next one."""
        with self._cond:
            return self._dropped + len(self._items)

    @property
    def items(self) -> list[T]:
        """The items kept, oldest first (a copy)."""
        with self._cond:
            return list(self._items)

    def since(self, start: int) -> list[T]:
        """The items kept from position `start` on."""
        with self._cond:
            return self._items[max(start - self._dropped, 0):]

    def last(self) -> T | None:
        with self._cond:
            return self._items[-1] if self._items else None

    def first(self, predicate: Callable[[T], bool], timeout_s: float,
              start: int = 0) -> tuple[int, T] | None:
        """(position, item) of the first item from position `start` on (arrived already
        or arriving within `timeout_s`) for which `predicate` holds; None at the timeout."""
        deadline = time.monotonic() + timeout_s
        i = start
        with self._cond:
            while True:
                for j in range(max(i - self._dropped, 0), len(self._items)):
                    if predicate(self._items[j]):
                        return self._dropped + j, self._items[j]
                i = max(i, self._dropped + len(self._items))
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._cond.wait(left)

    def wait(self, predicate: Callable[[T], bool], timeout_s: float, start: int = 0,
             what: str = "matching item") -> tuple[int, T]:
        """As `first`, but raises TimeoutError (saying `what` was awaited) at the timeout."""
        found = self.first(predicate, timeout_s, start)
        if found is None:
            raise TimeoutError(f"no {what} within {timeout_s:g} s among {len(self)} "
                               f"received; last: {self.last()!r}")
        return found
