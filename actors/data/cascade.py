"""Lock-step cascades: the outstanding work derived from one item the clock waits for (see
:mod:`aerodaas.actors.data.plane`: lock-step is a property of the clock, not of the transport)."""
from __future__ import annotations

import threading
import time
from typing import Callable

__all__ = ["Cascade"]


class Cascade:
    """Counts the outstanding work derived from one lock-step item (a frame or an odometry message).

    :meth:`add` when an item derived from it is accepted by a component (or sent to another actor), :meth:`done`
    when that item was processed and its outputs were handed on (or, for an item sent to another actor, when that
    actor answered that its own cascade for it is done); :meth:`wait` blocks until nothing is left. ``on_done``:
    called once, in the thread that finishes the last item, when the count drops to zero (``hold``: start at one,
    released by a :meth:`done` of the creator once it has seeded the cascade, so it cannot finish early)."""

    __slots__ = ("_n", "_cv", "_on_done")

    def __init__(self, on_done: Callable[[], None] | None = None, hold: bool = False) -> None:
        self._n = 1 if hold else 0
        self._cv = threading.Condition(threading.Lock())
        self._on_done = on_done

    def add(self) -> None:
        with self._cv:
            self._n += 1

    def done(self) -> None:
        fire = None
        with self._cv:
            self._n -= 1
            if self._n <= 0:
                self._cv.notify_all()
                fire, self._on_done = self._on_done, None
        if fire is not None:
            fire()

    @property
    def outstanding(self) -> int:
        """Items not yet done."""
        with self._cv:
            return self._n

    def wait(self, timeout_s: float = 120.0) -> None:
        """Block until every derived item is done. Raises TimeoutError after ``timeout_s`` seconds."""
        deadline = time.monotonic() + timeout_s
        with self._cv:
            while self._n > 0:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"lock-step: {self._n} items still in flight after {timeout_s:.0f} s")
                self._cv.wait(left)
