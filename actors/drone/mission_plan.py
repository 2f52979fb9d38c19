"""MissionPlanLog: the record of what happens to one robot's queued navigation besides flying it — the waypoint
plan on ``/<robot>/mission/plan`` (recorded when the queued waypoints change), the items discarded from the queue
(refused by the safety limits, executed actions, failed holds, aborted missions) and the pre-planned waypoints
cleared through the HITL API (the mission is then never a success).

The drone (which pops its queue as it flies) and its navigation inbox (which adds to and clears it) both write here;
it calls neither of them.
"""
from __future__ import annotations

import threading
from typing import Any

from aerodaas.model.types import Waypoint
from aerodaas.navigation.waypoint_queue import WaypointQueue


class MissionPlanLog:
    """See the module. ``home``: the robot's home (the plan's local ENU targets, metres); ``recorder``: the run's
    recorder or None; ``epoch_ns``: the run's epoch (nanoseconds) that simulated times (s) are added to."""

    def __init__(self, robot_id: str, home: Any, recorder: Any, epoch_ns: int) -> None:
        self.robot_id, self.home, self.recorder, self.epoch_ns = robot_id, home, recorder, epoch_ns
        self.discarded: list[dict] = []  # {"id", "t" (s), "reason"}; id "*": the whole queue (mission aborted)
        #: ids of pre-planned waypoints cleared through the HITL API: the mission is then never a success
        self.cleared_preplanned: list[str] = []
        self._sig: Any = None
        self._lock = threading.Lock()
        #: id(waypoint) -> (the waypoint, its entry in the recorded plan): a queued waypoint is never changed in
        #: place (:class:`~aerodaas.navigation.waypoint_queue.Mission`), so its entry is made once, not at every
        #: record (a visit records the plan of every waypoint still queued)
        self._items: dict[int, tuple[Any, dict]] = {}

    @property
    def recorded(self) -> bool:
        """Whether a plan was recorded yet."""
        return self._sig is not None

    def record_plan(self, queue: WaypointQueue, now: float) -> None:
        """Record ``queue``'s waypoints (with local ENU targets) at sim time ``now`` (s) when they changed since the
        last record. The plan's entries are shared between records (never changed after)."""
        with self._lock:  # snapshot, compare and record as one: the inbox and the drone's tick both record
            missions, known, cache = [], self._items, {}
            for m in queue.missions():
                items = []
                for w in m.items:
                    if isinstance(w, Waypoint):
                        entry = known.get(id(w))
                        if entry is None or entry[0] is not w:
                            entry = (w, {"id": w.id, "local": [round(c, 3) for c in w.to_local(self.home)],
                                         "hover_duration": w.hover_duration})
                        cache[id(w)] = entry
                        items.append(entry[1])
                if items:
                    missions.append({"name": m.name, "priority": m.priority, "items": items})
            self._items = cache  # the queued waypoints' entries only: the cache never outgrows the queue
            sig = [(m["name"], m["priority"], [i["id"] for i in m["items"]]) for m in missions]
            if sig == self._sig:
                return
            self._sig = sig
            if self.recorder is not None:
                self.recorder.json(f"/{self.robot_id}/mission/plan", self.epoch_ns + int(now * 1e9),
                                   {"robot": self.robot_id, "t": now, "missions": missions}, "aerodaas.MissionPlan")

    def complete(self, queue: WaypointQueue, item_id: str, now: float) -> bool:
        """The head waypoint ``item_id`` of ``queue`` was reached at ``now`` (s): pop it and record the plan.
        Returns False if no mission has it at its head."""
        ok = queue.complete(item_id)
        self.record_plan(queue, now)
        return ok

    def discard(self, queue: WaypointQueue, item_id: str, reason: str, now: float) -> bool:
        """Drop the head item ``item_id`` of ``queue`` without counting it as visited (rejected by safety, or an
        executed action) at ``now`` (s): logged with ``reason`` and the plan recorded. Returns False if no mission
        has it at its head."""
        if not queue.discard(item_id):
            return False
        self.discarded.append({"id": item_id, "t": now, "reason": reason})
        self.record_plan(queue, now)
        return True
