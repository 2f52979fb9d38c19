"""Stream edges between actors: bounded, latest-frame hand-off with drop counting, and lock-step waiting.

An :class:`Outlet` is the producer's end of one edge (producer -> consumer actor method). It allows
``buffer`` calls in flight; when the consumer is still busy with them, a new item is **dropped and counted**
instead of queued, so a slow consumer never stalls the camera or the control loop, and the consumer always
works on the newest frame available when it frees up. Frames travel as ObjectRefs wrapped in a list (so
Ray does not resolve them on the way): ``ray.put`` once, every consumer reads the same object, zero-copy on
the same node.

In lock-step mode, :meth:`Outlet.send` returns the call's ObjectRef and the producer waits with
:func:`wait_tree` for the consumer *and everything it triggered downstream* (consumers return the refs of
their own downstream calls) before simulated time moves on.
"""
from __future__ import annotations

from typing import Any

import ray


class Outlet:
    """Producer side of one edge to ``actor.<method>``. Not thread-safe; one producer thread per outlet."""

    def __init__(self, actor: Any, method: str, port: str, buffer: int = 1, lockstep: bool = False) -> None:
        self.actor = actor
        self.method = getattr(actor, method)
        self.port = port
        self.buffer = max(1, int(buffer))
        self.lockstep = lockstep
        self.in_flight: list = []
        self.sent = 0
        self.dropped = 0

    def send(self, *args: Any) -> Any:
        """Send one item; returns the call's ObjectRef, or None when the item was dropped (consumer busy)."""
        if not self.lockstep and self.in_flight:
            done, self.in_flight = ray.wait(self.in_flight, num_returns=len(self.in_flight), timeout=0)
            if len(self.in_flight) >= self.buffer:
                self.dropped += 1
                return None
        ref = self.method.remote(self.port, *args)
        self.sent += 1
        if not self.lockstep:
            self.in_flight.append(ref)
        return ref

    def stats(self) -> dict:
        return {"port": self.port, "sent": self.sent, "dropped": self.dropped}


def wait_tree(refs: list, timeout: float | None = 120.0) -> None:
    """Wait for ``refs`` and, recursively, for the refs their results list (a lock-step frame's whole cascade)."""
    pending = [r for r in refs if r is not None]
    while pending:
        results = ray.get(pending, timeout=timeout)
        pending = []
        for r in results:
            if isinstance(r, list):
                pending.extend(x for x in r if isinstance(x, ray.ObjectRef))
