"""The waypoint priority queue a drone flies from: missions by priority, preemption and resume, fixed ORDERED runs.

A queue holds *missions*: ``(priority, seq, name, items)`` where items are waypoints and/or velocity and action
commands. Lower priority numbers win (paper: ``PriorityQueue(data, priority)``). The head of the best non-empty
mission is what the drone executes; a higher-priority mission preempts the current one, and once it is exhausted
or cleared the preempted mission resumes at the waypoint it was heading to.

Fixed ORDERED runs: every waypoint in a mission has a segment id (``Mission.segment_ids``): 0 for waypoints that
came from UNORDERED navigation (free to re-order), n > 0 for waypoints of the ORDERED navigation n. When an
UNORDERED addition re-plans a mission, each run n is one node (entered at its first waypoint, left at its last)
that stays contiguous and in its order; only the free waypoints move between runs (the trajectory scheduler's
``order_segments``). An ORDERED addition inserted (``index=``) strictly inside a run joins that run; any other
ORDERED addition is a run of its own.

The queue only stores and hands out; it never plans. Who owns it: the drone (its running queue) and, before a
run, the application's trajectory scheduler (the pre-planned navigation handed to each drone at start). The
scheduler plans additions on a :meth:`WaypointQueue.copy` and the owner commits them
(:meth:`WaypointQueue.commit`). Thread-safe: every method takes the queue's lock.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

from aerodaas.model.types import VelocityCommand


@dataclass
class Mission:
    """One queued mission (one priority): ``items`` in flying order. ``segment_of`` maps ``id(item)`` to the item's
    segment id (absent = 0 = free, UNORDERED origin; n > 0 = part of the fixed ORDERED run n), so code that pops or
    inserts ``items`` directly cannot misalign it; pickling (Ray) carries it over by position."""

    priority: int
    seq: int
    name: str
    items: list = field(default_factory=list)
    distance_driven: bool = True
    segment_of: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def segment_ids(self) -> list[int]:
        """Segment id of each item (0 = free), parallel to ``items``."""
        return [self.segment_of.get(id(i), 0) for i in self.items]

    def set_segment_ids(self, ids: Sequence[int]) -> None:
        """Tag ``items`` (parallel ``ids``); forgets every other entry."""
        self.segment_of = {id(i): t for i, t in zip(self.items, ids) if t}

    def copy(self) -> "Mission":
        """A copy with its own item list and segment tags (the items themselves are shared)."""
        return Mission(self.priority, self.seq, self.name, list(self.items), self.distance_driven,
                       dict(self.segment_of))

    def __getstate__(self) -> dict:
        d = self.__dict__.copy()
        d["segment_of"] = self.segment_ids  # object ids do not survive pickling; positions do
        return d

    def __setstate__(self, d: dict) -> None:
        ids = d.pop("segment_of", [])
        self.__dict__.update(d)
        self.segment_of = {}
        if isinstance(ids, list):
            self.set_segment_ids(ids)


@dataclass(frozen=True)
class PlannedAddition:
    """Navigation planned by the trajectory scheduler (``TrajectoryScheduler.plan_addition``) on a copy of a
    queue, not yet queued: the ``priority`` it goes to, the planned ``mission`` of that priority (None: nothing to
    add), the ids (``id()``) of the items it adds and the copy's count of fixed runs after planning."""

    priority: int
    mission: Mission | None
    added: frozenset
    segments_issued: int


@dataclass(frozen=True)
class Order:
    """What the drone flies at one control tick (:meth:`WaypointQueue.order_at`): ``item`` (the head of the best
    queued mission: a Waypoint, a VelocityCommand or an ActionCommand; None: nothing queued), how many items of
    pre-planned (distance-driven) missions are left (``preplanned_left``), and the ``priority`` and name
    (``mission``) of the mission the item belongs to (None without an item)."""

    item: Any
    preplanned_left: int
    priority: int | None = None
    mission: str | None = None


def _flying_order(m: Mission) -> tuple[int, int]:
    return m.priority, m.seq


class WaypointQueue:
    """One robot's waypoint priority queue (see the module). ``missions``: the initial missions (taken as given).

    :attr:`completed` lists the ids of the waypoints reached, :attr:`cleared` counts the aborts
    (:meth:`remove_queued`)."""

    def __init__(self, missions: Sequence[Mission] = (), seq: int = 0, segments_issued: int = 0) -> None:
        self._missions: list[Mission] = list(missions)
        self._seq = seq
        self._segments_issued = segments_issued
        self._lock = threading.RLock()
        self.completed: list[str] = []
        self.cleared = 0

    def __getstate__(self) -> dict:
        d = self.__dict__.copy()
        d.pop("_lock", None)
        return d

    def __setstate__(self, d: dict) -> None:
        self.__dict__.update(d)
        self._lock = threading.RLock()

    @property
    def seq(self) -> int:
        """How many missions were ever created in this queue (each new mission's age)."""
        return self._seq

    @property
    def segments_issued(self) -> int:
        """How many fixed ORDERED runs were ever issued (the last segment id)."""
        return self._segments_issued

    @property
    def entries(self) -> list[Mission]:
        """The live missions in the order they were queued (not copies: for the planner working on its own
        :meth:`copy`, and for tests). Everyone else reads :meth:`missions`."""
        return self._missions

    def copy(self) -> "WaypointQueue":
        """A queue of its own with copies of the missions (the items themselves are shared), the same counters and
        no completed ids: what the trajectory scheduler plans on (taken under the lock, consistent)."""
        with self._lock:
            return WaypointQueue([m.copy() for m in self._missions], self._seq, self._segments_issued)

    # ------------------------------------------------------------------ adding (the planner's primitives)
    def mission_at(self, priority: int) -> Mission | None:
        """The live mission at ``priority`` (None: none queued)."""
        with self._lock:
            for m in self._missions:
                if m.priority == priority:
                    return m
            return None

    def new_segment_id(self) -> int:
        """Issue the id of a new fixed ORDERED run (1, 2, ...)."""
        with self._lock:
            self._segments_issued += 1
            return self._segments_issued

    def enqueue(self, name: str, items: Sequence, priority: int, distance_driven: bool = True,
                fixed: bool = False) -> Mission:
        """Queue a new mission ``name`` of ``items`` (in flying order) at ``priority``; ``fixed``: the items are one
        ORDERED run (a new segment id). Returns the live mission."""
        with self._lock:
            self._seq += 1
            m = Mission(priority, self._seq, name, list(items), distance_driven)
            if fixed:
                m.set_segment_ids([self.new_segment_id()] * len(m.items))
            self._missions.append(m)
            return m

    def insert(self, items: Sequence, priority: int, index: int | None = None, fixed: bool = False) -> Mission:
        """Put ``items`` into the existing mission at ``priority`` at ``index`` (None: at its end). ``fixed``
        (ORDERED) items inserted strictly inside a fixed run join that run, otherwise they are a run of their own;
        free items get segment id 0. Returns the live mission. Raises KeyError when no mission has ``priority``,
        IndexError for an ``index`` outside ``0..len(items)``."""
        with self._lock:
            m = self.mission_at(priority)
            if m is None:
                raise KeyError(f"no mission at priority {priority}")
            tags = m.segment_ids
            if index is None:
                index = len(m.items)
            elif not 0 <= index <= len(m.items):
                raise IndexError(f"index {index} out of range for a mission of {len(m.items)} items")
            if not fixed:
                tag = 0
            elif 0 < index < len(tags) and tags[index - 1] == tags[index] != 0:
                tag = tags[index]  # inserted strictly inside a fixed run: it joins the run
            else:
                tag = self.new_segment_id()
            m.items[index:index] = list(items)
            tags[index:index] = [tag] * len(items)
            m.set_segment_ids(tags)
            return m

    def commit(self, plan: PlannedAddition) -> None:
        """Put a planned addition into the queue, keeping what happened since it was planned: items reached or
        discarded meanwhile stay gone, items added by others meanwhile stay (after the plan's)."""
        planned = plan.mission
        if planned is None:
            return
        with self._lock:
            real = self.mission_at(plan.priority)
            alive = {id(i) for i in real.items} if real is not None else set()
            in_plan = {id(i) for i in planned.items}
            items = [i for i in planned.items if id(i) in alive or id(i) in plan.added]
            items += [i for i in (real.items if real is not None else []) if id(i) not in in_plan]
            tags = [planned.segment_of.get(id(i), real.segment_of.get(id(i), 0) if real is not None else 0)
                    for i in items]
            self._segments_issued = max(self._segments_issued, plan.segments_issued)
            if real is None:
                self._seq += 1
                real = Mission(plan.priority, self._seq, planned.name, [], planned.distance_driven)
                self._missions.append(real)
            real.items = items
            real.set_segment_ids(tags)

    # ------------------------------------------------------------------ removing
    def remove_queued(self, drop: Callable[[Any], bool], priority: int | None = None) -> list:
        """Abort part of the queue: remove every queued item for which ``drop(item)`` is true, from every mission
        (or only the missions at ``priority``), in one step under the queue's lock; missions left empty are
        dropped, and :attr:`cleared` counts the call (even when nothing matched). Returns the removed items in
        queue order. ``drop`` runs under the lock: it must not call back into this queue. Raises what ``drop``
        raises (the queue is then unchanged)."""
        with self._lock:
            gone: list = []
            kept: dict[int, list] = {}  # id(mission) -> the items it keeps
            for m in self._missions:
                if priority is None or m.priority == priority:
                    kept[id(m)] = []
                    for i in m.items:
                        (gone if drop(i) else kept[id(m)]).append(i)
            for m in self._missions:
                if id(m) in kept:
                    m.items = kept[id(m)]
            self._missions = [m for m in self._missions if m.items]
            self.cleared += 1
            return gone

    def revise_items(self, revise: Callable[[Mission], Sequence]) -> None:
        """Replace the items of every queued mission by ``revise(copy of the mission)`` (missions in the order they
        were queued), e.g. the pre-flight safety check putting clamped waypoints in place of the originals. All or
        nothing, under the queue's lock: if ``revise`` raises for any mission, the queue is unchanged and the error
        propagates. A revised list of the same length keeps each position's segment id (a clamped waypoint of a
        fixed ORDERED run stays in its run); one of another length is free (segment id 0). ``revise`` must not call
        back into this queue."""
        with self._lock:
            revised = [list(revise(m.copy())) for m in self._missions]
            for m, items in zip(self._missions, revised):
                tags = m.segment_ids
                m.items = items
                m.set_segment_ids(tags if len(tags) == len(items) else [])

    # ------------------------------------------------------------------ flying
    def current(self, now: float) -> tuple[Mission, Any] | None:
        """The (mission, item) the drone should execute at sim time ``now`` (s); expired velocity commands (and
        ones superseded by a newer command) are dropped. None: nothing queued."""
        with self._lock:
            for m in sorted(self._missions, key=_flying_order):
                while m.items and isinstance(m.items[0], VelocityCommand):
                    v = m.items[0]
                    if v.issued_at is None:
                        v.issued_at = now
                    if now - v.issued_at >= v.duration or (len(m.items) > 1 and isinstance(m.items[1], VelocityCommand)):
                        m.items.pop(0)  # expired, or superseded by a newer command
                        continue
                    break
                if m.items:
                    return m, m.items[0]
            self._missions = [m for m in self._missions if m.items]
            return None

    def order_at(self, now: float) -> Order:
        """What to fly at sim time ``now`` (s): :meth:`current` and the pre-planned items left, as an :class:`Order`."""
        with self._lock:
            cur = self.current(now)
            left = self.pending(distance_driven_only=True)
        if cur is None:
            return Order(None, left)
        m, item = cur
        return Order(item, left, m.priority, m.name)

    def complete(self, item_id: str) -> bool:
        """Mark the head waypoint ``item_id`` of its mission as reached and pop it. Returns False if not at a head."""
        with self._lock:
            if not self.discard(item_id):
                return False
            self.completed.append(item_id)
            return True

    def discard(self, item_id: str) -> bool:
        """Pop the head item ``item_id`` of its mission without counting it as reached (an item refused by the
        safety limits, or an executed action). Returns False if no mission has it at its head."""
        with self._lock:
            for m in self._missions:
                if m.items and getattr(m.items[0], "id", None) == item_id:
                    m.items.pop(0)
                    return True
            return False

    # ------------------------------------------------------------------ reading
    def pending(self, distance_driven_only: bool = False) -> int:
        """Number of queued items (optionally only in pre-planned, distance-driven missions)."""
        with self._lock:
            return sum(len(m.items) for m in self._missions if m.distance_driven or not distance_driven_only)

    def queued(self) -> list:
        """Every queued item in the order the drone would fly them (missions by priority, then age), e.g. to upload
        a pre-planned mission to an autopilot in one go."""
        with self._lock:
            return [i for m in sorted(self._missions, key=_flying_order) for i in m.items]

    def missions(self) -> list[Mission]:
        """Copies of the queued missions in flying order (priority, then age): the lists and segment tags are
        copies, the items themselves are shared (they are never changed in place)."""
        with self._lock:
            return [m.copy() for m in sorted(self._missions, key=_flying_order)]

    def snapshot(self) -> list[dict]:
        """The queue as JSON-ready dicts in flying order: ``[{"name", "priority", "items": [item dumps]}]``."""
        with self._lock:
            return [{"name": m.name, "priority": m.priority, "items": [i.model_dump() for i in m.items]}
                    for m in sorted(self._missions, key=_flying_order)]

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> dict:
        """The queue for a checkpoint: ``{"missions": [Mission copies], "completed": [ids], "seq": n,
        "segments_issued": n}`` (consistent: taken under the queue's lock)."""
        with self._lock:
            return {"missions": [m.copy() for m in self._missions], "completed": list(self.completed),
                    "seq": self._seq, "segments_issued": self._segments_issued}

    def restore(self, missions: list[Mission], completed: list[str], seq: int | None = None,
                segments_issued: int | None = None) -> None:
        """Put a :meth:`state` back (a restarted drone actor resuming its mission)."""
        with self._lock:
            self._missions = list(missions)
            self.completed = list(completed)
            if seq is not None:
                self._seq = seq
            if segments_issued:
                self._segments_issued = segments_issued
