"""Time of the analytics dispatcher: the policies' millisecond clock (:class:`Clock`) and absolute-time asyncio
timers (:func:`set_result_if_pending`, the callback of a ``loop.call_at`` that ends a wait).

Times given to policies are ms on the dispatcher's :class:`Clock` (``time.monotonic`` since the run's ``t0``).
Times that cross processes (cloud hold targets, the cloud re-check) are epoch seconds (``time.time``): exact on one
machine, NTP-accurate across machines.
"""
from __future__ import annotations

import asyncio
import time
from typing import Any

__all__ = ["Clock", "set_result_if_pending"]


class Clock:
    """Milliseconds since ``t0`` on ``time.monotonic`` (the policies' ``now_ms``).

    ``t0`` (monotonic seconds) defaults to now. :meth:`loop_time` converts a clock time to an asyncio loop time and
    :meth:`epoch` to epoch seconds (``time.time``), for times that cross processes.
    """

    def __init__(self, t0: float | None = None) -> None:
        self.t0 = time.monotonic() if t0 is None else float(t0)

    @classmethod
    def at_epoch(cls, start_epoch: float) -> "Clock":
        """A clock whose 0 ms is the epoch time ``start_epoch`` (s), so several processes share one time origin."""
        return cls(time.monotonic() + (start_epoch - time.time()))

    def now_ms(self) -> float:
        return (time.monotonic() - self.t0) * 1000.0

    def loop_time(self, loop: asyncio.AbstractEventLoop, t_ms: float) -> float:
        return loop.time() + (t_ms - self.now_ms()) / 1000.0

    def epoch(self, t_ms: float) -> float:
        return time.time() + (t_ms - self.now_ms()) / 1000.0


def set_result_if_pending(fut: asyncio.Future, value: Any) -> None:
    if not fut.done():
        fut.set_result(value)
