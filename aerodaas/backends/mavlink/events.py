"""The MAVLink backend's event log: every concern records its events here (``connected``, ``mode``, ``link_lost``,
``autopilot_failsafe``, ``speed_margin``...), each stamped with the vehicle clock's time, and the drone drains them
(:meth:`~aerodaas.backends.base.VehicleBackend.drain_events`)."""
from __future__ import annotations

from collections import deque
from typing import Any

from aerodaas.backends.mavlink.clock import VehicleClock

#: events kept until drained; the oldest are dropped beyond this (the drone drains every control step)
EVENT_QUEUE = 2000


class EventLog:
    """Events of one vehicle's concerns, oldest first. Calling it, ``log("name", **fields)``, records
    ``{"event": name, "t": vehicle seconds (VehicleClock.t, extrapolated while the link is down, 3 decimals),
    **fields}`` from any thread; :meth:`drain` hands them out. Raises nothing."""

    def __init__(self, clock: VehicleClock, maxlen: int = EVENT_QUEUE) -> None:
        self._clock = clock
        self._events: deque[dict[str, Any]] = deque(maxlen=maxlen)

    def __call__(self, event: str, **fields: Any) -> None:
        self._events.append({"event": event, "t": round(self._clock.t, 3), **fields})

    def drain(self) -> list[dict[str, Any]]:
        """Every event recorded and not yet drained, oldest first (safe against concurrent recording)."""
        out = []
        while self._events:
            try:
                out.append(self._events.popleft())
            except IndexError:
                break
        return out
