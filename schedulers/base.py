"""The trajectory-scheduler contract (the paper's INavigate) and the waypoint priority queue behind it.

A scheduler holds *missions*: ``(priority, seq, name, items)`` where items are waypoints and/or velocity
commands. Lower priority numbers win (paper: ``PriorityQueue(data, priority)``). The head of the best
non-empty mission is what the drone executes; a higher-priority mission preempts the current one, and once
it is exhausted or cleared the preempted mission resumes at the waypoint it was heading to.

Plug-ins subclass :class:`TrajectoryScheduler` and override :meth:`order` (how an UNORDERED list is sequenced).

Fixed ORDERED runs: every waypoint in a mission has a segment id (``Mission.segment_ids``): 0 for waypoints that
came from UNORDERED navigation (free to re-order), n > 0 for waypoints of the ORDERED navigation n. When an
UNORDERED addition re-plans a mission, each run n is one node (entered at its first waypoint, left at its last)
that stays contiguous and in its order; only the free waypoints move between runs
(:meth:`TrajectoryScheduler.order_segments`). An ORDERED addition inserted (``index=``) strictly inside a run joins
that run; any other ORDERED addition is a run of its own.
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Sequence

from aerodaas.app.models import AeroNavigation, PriorityQueue, SchedulingType, VelocityCommand, Waypoint

DEFAULT_PRIORITY = 2


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
    """Navigation planned by :meth:`TrajectoryScheduler.plan_addition`, not yet queued: the ``priority`` it goes
    to, the planned ``mission`` of that priority (None: nothing to add), the ids (``id()``) of the items it adds
    and the scheduler's count of fixed runs after planning."""

    priority: int
    mission: Mission | None
    added: frozenset
    segments_issued: int


class TrajectoryScheduler:
    """Base trajectory scheduler (INavigate): keeps the given order (ORDERED); subclasses re-order UNORDERED.

    Thread-safe. Positions are ENU metres relative to the drone's home.
    """

    name = "ordered"
    #: plug-in declaration (aerodaas.plugins.registry): registered under its class name (or ``plugin_name``)
    plugin_kind = "trajectory_scheduler"
    consumes: tuple = ("navigation",)
    produces: tuple = ("waypoint_order",)

    def __init__(self, env: Any = None, start: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        self.env = env
        self.start = tuple(float(v) for v in start)
        self._missions: list[Mission] = []
        self._seq = 0
        self._lock = threading.RLock()
        self.completed: list[str] = []
        self.cleared = 0
        self.stream_inputs: list[tuple[Any, int, bool]] = []  # (AeroStreamData, priority, replace) wired at start
        self._remote = None  # the scheduler component's handle while a mission runs
        if env is not None and hasattr(env, "adopt_scheduler"):
            env.adopt_scheduler(self)

    def __getstate__(self) -> dict:
        d = self.__dict__.copy()
        d.pop("_lock", None)
        d["env"] = None
        d["_remote"] = None
        d["stream_inputs"] = []
        return d

    def __setstate__(self, d: dict) -> None:
        self.__dict__.update(d)
        self._lock = threading.RLock()

    def fork(self, missions: list[Mission]) -> "TrajectoryScheduler":
        """A scheduler of the same class and settings holding only ``missions`` (each robot of a fleet gets its
        own waypoint queue when an application plugs one scheduler into the environment). Analytics stream
        inputs are kept: their navigation carries the robot it is meant for."""
        import copy

        with self._lock:
            twin = copy.copy(self)
            twin._lock = threading.RLock()
            twin._missions = list(missions)
            twin.completed = []
            twin.stream_inputs = list(self.stream_inputs)
            twin._remote = None
        return twin

    def bind_remote(self, handle: Any) -> None:
        """While a mission runs, route :meth:`add_navigation` and :meth:`clear_navigation` to the robot's running
        scheduler component ``handle`` (a :class:`~aerodaas.runtime.handles.SchedulerHandle`), which holds the live
        queue; ``None`` (after the run) makes them act on this object's own queue again. Not pickled."""
        self._remote = handle

    # ------------------------------------------------------------------ ordering (plug-in point)
    def order(self, waypoints: list[Waypoint], start: Sequence[float]) -> list[Waypoint]:
        """Return the visiting order for an UNORDERED list. The base class keeps the given order."""
        return list(waypoints)

    def order_segments(self, segments: list[list[Waypoint]], start: Sequence[float]) -> list[list[Waypoint]]:
        """Order *nodes* for an open path from ``start``: each inner list is flown as given (a fixed ORDERED run,
        entered at its first waypoint and left at its last, or a single free waypoint). Return the same inner
        lists, re-ordered. With only single waypoints this is :meth:`order`; otherwise, by default, :meth:`order`
        sequences the runs by their first waypoint. Override it to plan with the runs' exits too."""
        if all(len(seg) == 1 for seg in segments):
            return [[w] for w in self.order([seg[0] for seg in segments], start)]
        by_head: dict[int, list[list[Waypoint]]] = {}
        for seg in segments:
            by_head.setdefault(id(seg[0]), []).append(seg)
        out = []
        for w in self.order([seg[0] for seg in segments], start):
            if not by_head.get(id(w)):
                break
            out.append(by_head[id(w)].pop(0))
        if len(out) != len(segments):
            raise ValueError(f"{type(self).__name__}.order() must return the waypoints it was given, each once")
        return out

    @staticmethod
    def tour_length(waypoints: Iterable[Waypoint], start: Sequence[float]) -> float:
        """Length in metres of the polyline start -> waypoints (relative coordinates)."""
        p = tuple(start)
        total = 0.0
        for w in waypoints:
            q = (w.x, w.y, w.z)
            total += math.dist(p, q)
            p = q
        return total

    # ------------------------------------------------------------------ INavigate
    def generate_navigation(self, nav: AeroNavigation | PriorityQueue | list, priority: int | None = None) -> AeroNavigation:
        """Schedule ``nav`` (order it if UNORDERED) and enqueue it; returns the scheduled AeroNavigation.

        Accepts an AeroNavigation, a PriorityQueue wrapping one (or a list of waypoints), or a plain list.
        Raises TypeError for anything else."""
        nav, prio = self.unwrap_navigation(nav, priority)
        scheduled = self.schedule(nav)
        self._enqueue(scheduled, prio, fixed=nav.scheduling_type == SchedulingType.ORDERED)
        return scheduled

    #: bounded work: an UNORDERED navigation of more waypoints is refused (ValueError) before any planning
    #: (nearest neighbour is O(n^2): 2000 waypoints ~ 2 s on a loaded 2-core machine). Set per instance or subclass.
    max_waypoints = 2000

    def schedule(self, nav: AeroNavigation, start: Sequence[float] | None = None) -> AeroNavigation:
        """Order ``nav`` without enqueueing it. Raises ValueError for more than :attr:`max_waypoints` waypoints."""
        if nav.scheduling_type == SchedulingType.UNORDERED:
            wps = [w for w in nav.waypoints if isinstance(w, Waypoint)]
            if len(wps) > self.max_waypoints:
                raise ValueError(f"navigation {nav.name!r}: {len(wps)} UNORDERED waypoints, more than the scheduler's "
                                 f"max_waypoints ({self.max_waypoints}); split it or raise the limit")
            others = [w for w in nav.waypoints if not isinstance(w, Waypoint)]
            ordered = self.order(wps, start if start is not None else self.start) + others
            return nav.model_copy(update={"waypoints": ordered, "scheduling_type": SchedulingType.ORDERED})
        return nav

    def add_navigation(self, nav: AeroNavigation | PriorityQueue | list, index: int | None = None,
                       priority: int | None = None, position: Sequence[float] | None = None) -> None:
        """Add navigation at ``priority`` (default: the PriorityQueue's, else 2). With ``index``, insert the items at
        that index of the existing mission of the same priority (the paper's "append at custom indices");
        otherwise extend it (or create it). UNORDERED additions re-plan the remaining waypoints of that mission
        from ``position`` (the drone's current position if given).

        A ``PriorityQueue`` wrapping an analytics output stream (AeroStreamData) wires that stream into this
        scheduler: every AeroNavigation it carries is added at that priority while the mission runs."""
        data = nav.data if isinstance(nav, PriorityQueue) else nav
        if type(data).__name__ == "AeroStreamData":
            self.stream_inputs.append((data, nav.priority if isinstance(nav, PriorityQueue) and priority is None
                                       else (priority if priority is not None else DEFAULT_PRIORITY),
                                       bool(getattr(nav, "replace", False))))
            return
        if self._remote is not None:
            import ray

            nav_, prio_ = self.unwrap_navigation(nav, priority)
            ray.get(self._remote.add_navigation.remote(nav_, index, prio_))
            return
        nav, prio = self.unwrap_navigation(nav, priority)
        with self._lock:
            m = self._find(prio)
            fixed = nav.scheduling_type == SchedulingType.ORDERED
            if m is None:
                self._enqueue(self.schedule(nav, position), prio, fixed=fixed)
                return
            items = list(nav.waypoints)
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
                tag = self._new_segment_id()
            m.items[index:index] = items
            tags[index:index] = [tag] * len(items)
            m.set_segment_ids(tags)
            if not fixed:
                self._replan(m, position if position is not None else self.start)

    def clear_navigation(self, priority: int | None = None) -> None:
        """Abort: drop every queued mission (or only those at ``priority``). A cleared mission never resumes."""
        if self._remote is not None:
            import ray

            ray.get(self._remote.clear_navigation.remote(priority))
            return
        self.remove_queued(lambda _item: True, priority)

    def remove_queued(self, drop: Callable[[Any], bool], priority: int | None = None) -> list:
        """Abort part of the queue: remove every queued item for which ``drop(item)`` is true, from every mission
        (or only the missions at ``priority``), in one step under the queue's lock; missions left empty are
        dropped, and :attr:`cleared` counts the call (even when nothing matched). Returns the removed items in
        queue order. Acts on this scheduler's own queue (never forwarded to a running scheduler component).
        ``drop`` runs under the lock: it must not call back into this scheduler. Raises what ``drop`` raises (the
        queue is then unchanged)."""
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
        back into this scheduler."""
        with self._lock:
            revised = [list(revise(m.copy())) for m in self._missions]
            for m, items in zip(self._missions, revised):
                tags = m.segment_ids
                m.items = items
                m.set_segment_ids(tags if len(tags) == len(items) else [])

    # ------------------------------------------------------------------ execution side
    def current(self, now: float) -> tuple[Mission, Any] | None:
        """The (mission, item) the drone should execute at sim time ``now``; expired velocity commands are dropped."""
        with self._lock:
            for m in sorted(self._missions, key=lambda m: (m.priority, m.seq)):
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

    def pending(self, distance_driven_only: bool = False) -> int:
        """Number of queued items (optionally only in pre-planned, distance-driven missions)."""
        with self._lock:
            return sum(len(m.items) for m in self._missions if m.distance_driven or not distance_driven_only)

    def queued(self) -> list:
        """Every queued item in the order the drone would fly them (missions by priority, then age), e.g. to upload
        a pre-planned mission to an autopilot in one go."""
        with self._lock:
            return [i for m in sorted(self._missions, key=lambda m: (m.priority, m.seq)) for i in m.items]

    # ------------------------------------------------------------------ the queue, for the drone actor that owns it
    def missions(self) -> list[Mission]:
        """Copies of the queued missions in flying order (priority, then age): the lists and segment tags are
        copies, the items themselves are shared (they are never changed in place)."""
        with self._lock:
            return [m.copy() for m in sorted(self._missions, key=lambda m: (m.priority, m.seq))]

    def plan_addition(self, nav: AeroNavigation, index: int | None, priority: int,
                      position: Sequence[float]) -> "PlannedAddition":
        """Plan adding ``nav`` at ``priority`` (``index``: as :meth:`add_navigation`) from ``position`` (ENU
        metres) on a copy of the queue: the queue is neither changed nor locked while :meth:`order` runs, so a long
        re-plan never holds the drone's control tick. Commit it with :meth:`commit_addition`. Raises IndexError
        when ``index`` is beyond the end of that priority's mission, and what :meth:`add_navigation` raises."""
        with self._lock:
            snap = [m.copy() for m in self._missions]
            cur = self._find(priority)
            n = len(cur.items) if cur is not None else 0
            if index is not None and index > n:
                raise IndexError(f"index: {index} is out of range for the priority-{priority} mission of {n} items")
        twin = self.fork(snap)
        twin.add_navigation(nav, index=index, priority=priority, position=position)
        planned = twin._find(priority)
        return PlannedAddition(priority, planned.copy() if planned is not None else None,
                               frozenset(id(i) for i in nav.waypoints), getattr(twin, "_segments_issued", 0))

    def commit_addition(self, plan: "PlannedAddition") -> None:
        """Put a :meth:`plan_addition` result into the queue, keeping what happened since it was planned: items
        reached or discarded meanwhile stay gone, items added by others meanwhile stay (after the plan's)."""
        planned = plan.mission
        if planned is None:
            return
        with self._lock:
            real = self._find(plan.priority)
            alive = {id(i) for i in real.items} if real is not None else set()
            in_plan = {id(i) for i in planned.items}
            items = [i for i in planned.items if id(i) in alive or id(i) in plan.added]
            items += [i for i in (real.items if real is not None else []) if id(i) not in in_plan]
            tags = [planned.segment_of.get(id(i), real.segment_of.get(id(i), 0) if real is not None else 0)
                    for i in items]
            if plan.segments_issued > getattr(self, "_segments_issued", 0):
                self._segments_issued = plan.segments_issued
            if real is None:
                self._seq += 1
                real = Mission(plan.priority, self._seq, planned.name, [], planned.distance_driven)
                self._missions.append(real)
            real.items = items
            real.set_segment_ids(tags)

    def queue_state(self) -> dict:
        """The queue for a checkpoint: ``{"missions": [Mission copies], "completed": [ids], "seq": n,
        "segments_issued": n}`` (consistent: taken under the queue's lock)."""
        with self._lock:
            return {"missions": [m.copy() for m in self._missions], "completed": list(self.completed),
                    "seq": self._seq, "segments_issued": getattr(self, "_segments_issued", 0)}

    def restore_queue(self, missions: list[Mission], completed: list[str], seq: int | None = None,
                      segments_issued: int | None = None) -> None:
        """Put a :meth:`queue_state` back (a restarted drone actor resuming its mission)."""
        with self._lock:
            self._missions = list(missions)
            self.completed = list(completed)
            if seq is not None:
                self._seq = seq
            if segments_issued:
                self._segments_issued = segments_issued

    def snapshot(self) -> list[dict]:
        with self._lock:
            return [{"name": m.name, "priority": m.priority, "items": [i.model_dump() for i in m.items]}
                    for m in sorted(self._missions, key=lambda m: (m.priority, m.seq))]

    # ------------------------------------------------------------------ internals
    def _find(self, priority: int) -> Mission | None:
        for m in self._missions:
            if m.priority == priority:
                return m
        return None

    def _enqueue(self, nav: AeroNavigation, priority: int, fixed: bool = False) -> None:
        with self._lock:
            self._seq += 1
            m = Mission(priority, self._seq, nav.name, list(nav.waypoints),
                        nav.navigation_type.value == "DISTANCE_DRIVEN")
            if fixed:
                m.set_segment_ids([self._new_segment_id()] * len(m.items))
            self._missions.append(m)

    def _new_segment_id(self) -> int:
        self._segments_issued = getattr(self, "_segments_issued", 0) + 1
        return self._segments_issued

    def _replan(self, m: Mission, start: Sequence[float]) -> None:
        """Re-order ``m``'s waypoints from ``start``: fixed runs as single nodes, free waypoints individually;
        velocity commands keep their relative order after the waypoints."""
        segs: list[list[Waypoint]] = []
        seg_tag: dict[int, int] = {}  # id(first waypoint of a node) -> segment id
        run_index: dict[int, int] = {}  # segment id -> index in segs
        rest, rest_tags = [], []
        for item, tag in zip(m.items, m.segment_ids):
            if not isinstance(item, Waypoint):
                rest.append(item)
                rest_tags.append(tag)
            elif tag and tag in run_index:
                segs[run_index[tag]].append(item)
            else:
                if tag:
                    run_index[tag] = len(segs)
                seg_tag[id(item)] = tag
                segs.append([item])
        items, tags = [], []
        for seg in self.order_segments(segs, start):
            items.extend(seg)
            tags.extend([seg_tag[id(seg[0])]] * len(seg))
        m.items = items + rest
        m.set_segment_ids(tags + rest_tags)

    @staticmethod
    def unwrap_navigation(nav: Any, priority: int | None) -> tuple[AeroNavigation, int]:
        """``(AeroNavigation, priority)`` from an AeroNavigation, a PriorityQueue wrapping one (or a list of
        waypoints) or a plain list; ``priority`` overrides the PriorityQueue's (default 2). Raises TypeError for
        anything else."""
        prio = priority
        if isinstance(nav, PriorityQueue):
            prio = nav.priority if priority is None else priority
            nav = nav.data
        if hasattr(nav, "get_data") and not isinstance(nav, AeroNavigation):
            nav = nav.get_data()
        if isinstance(nav, list):
            nav = AeroNavigation(waypoints=nav)
        if not isinstance(nav, AeroNavigation):
            raise TypeError(f"expected AeroNavigation, PriorityQueue or a list of waypoints, got {type(nav).__name__}")
        return nav, DEFAULT_PRIORITY if prio is None else prio
