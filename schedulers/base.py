"""The trajectory-scheduler contract (the paper's INavigate): the planner a drone asks to sequence navigation.

Plug-ins subclass :class:`TrajectoryScheduler` and override :meth:`~TrajectoryScheduler.order` (how an UNORDERED
list is sequenced; :meth:`~TrajectoryScheduler.order_segments` to plan with fixed ORDERED runs' exits too).

The scheduler does not fly anything and never calls a drone. Before a run it keeps the navigation the application
queued (``generate_navigation``, ``add_navigation``) in a :class:`~aerodaas.navigation.waypoint_queue.WaypointQueue`
of its own (:attr:`TrajectoryScheduler.queue`); at start each drone gets a copy of its share and owns it. While the
run goes on, the drone's navigation inbox (:class:`aerodaas.actors.drone.scheduler_component.SchedulerComponent`) asks
the scheduler to plan each addition on a copy of the drone's queue (:meth:`TrajectoryScheduler.plan_addition`) and
commits the result into that queue (:meth:`WaypointQueue.commit`). The queue, its missions, priorities,
preemption and fixed ORDERED runs are described in :mod:`aerodaas.navigation.waypoint_queue`.
"""
from __future__ import annotations

import copy
import math
from typing import Any, Callable, Iterable, Sequence

from aerodaas.model.types import AeroNavigation, PriorityQueue, SchedulingType, Waypoint
from aerodaas.navigation.waypoint_queue import Mission, PlannedAddition, WaypointQueue

__all__ = ["DEFAULT_PRIORITY", "Mission", "PlannedAddition", "TrajectoryScheduler", "WaypointQueue"]

DEFAULT_PRIORITY = 2


class TrajectoryScheduler:
    """Base trajectory scheduler (INavigate): keeps the given order (ORDERED); subclasses re-order UNORDERED.

    Positions are ENU metres relative to the drone's home. :attr:`queue` holds the navigation queued through this
    object (thread-safe, see :class:`~aerodaas.navigation.waypoint_queue.WaypointQueue`); the planning methods
    (:meth:`plan_addition`, :meth:`add_to`) work on whichever queue they are given.
    """

    name = "ordered"
    #: plug-in declaration (aerodaas.plugins.registry): registered under its class name (or ``plugin_name``)
    plugin_kind = "trajectory_scheduler"
    consumes: tuple = ("navigation",)
    produces: tuple = ("waypoint_order",)

    def __init__(self, env: Any = None, start: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
        self.env = env
        self.start = tuple(float(v) for v in start)
        #: the navigation queued through this scheduler (before a run: the pre-planned missions each drone gets)
        self.queue = WaypointQueue()
        self.stream_inputs: list[tuple[Any, int, bool]] = []  # (AeroStreamData, priority, replace) wired at start
        self._remote = None  # the robot's navigation inbox handle while a mission runs
        if env is not None and hasattr(env, "adopt_scheduler"):
            env.adopt_scheduler(self)

    def __getstate__(self) -> dict:
        d = self.__dict__.copy()
        d["env"] = None
        d["_remote"] = None
        d["stream_inputs"] = []
        return d

    def fork(self, missions: list[Mission]) -> "TrajectoryScheduler":
        """A scheduler of the same class and settings whose queue holds only ``missions`` (each robot of a fleet
        gets its own share when an application plugs one scheduler into the environment). Analytics stream inputs
        are kept: their navigation carries the robot it is meant for."""
        twin = copy.copy(self)
        twin.queue = WaypointQueue(missions, self.queue.seq, self.queue.segments_issued)
        twin.stream_inputs = list(self.stream_inputs)
        twin.bind_remote(None)
        return twin

    def bind_remote(self, handle: Any) -> None:
        """While a mission runs, route :meth:`add_navigation` and :meth:`clear_navigation` to the robot's running
        navigation inbox ``handle`` (a :class:`~aerodaas.actors.builtin.handles.SchedulerHandle`), which fills the drone's
        live queue; ``None`` (after the run) makes them act on :attr:`queue` again. Not pickled."""
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
        """Schedule ``nav`` (order it if UNORDERED) and enqueue it in :attr:`queue`; returns the scheduled
        AeroNavigation.

        Accepts an AeroNavigation, a PriorityQueue wrapping one (or a list of waypoints), or a plain list.
        Raises TypeError for anything else."""
        nav, prio = self.unwrap_navigation(nav, priority)
        scheduled = self.schedule(nav)
        self._enqueue(self.queue, scheduled, prio, fixed=nav.scheduling_type == SchedulingType.ORDERED)
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
        from ``position`` (the drone's current position if given). While a mission runs (:meth:`bind_remote`) the
        navigation goes to the robot's inbox, which checks and plans it for the drone's live queue.

        A ``PriorityQueue`` wrapping an analytics output stream (AeroStreamData) wires that stream into the robot's
        inbox: every AeroNavigation it carries is added at that priority while the mission runs. Raises TypeError,
        IndexError, ValueError as :meth:`add_to`."""
        data = nav.data if isinstance(nav, PriorityQueue) else nav
        if type(data).__name__ == "AeroStreamData":
            self.stream_inputs.append((data, nav.priority if isinstance(nav, PriorityQueue) and priority is None
                                       else (priority if priority is not None else DEFAULT_PRIORITY),
                                       bool(getattr(nav, "replace", False))))
            return
        nav, prio = self.unwrap_navigation(nav, priority)
        if self._remote is not None:
            import ray  # lazy: heavy ray

            ray.get(self._remote.add_navigation.remote(nav, index, prio))
            return
        self.add_to(self.queue, nav, index, prio, position)

    def add_to(self, queue: WaypointQueue, nav: AeroNavigation, index: int | None, priority: int,
               position: Sequence[float] | None = None) -> None:
        """Plan ``nav`` into ``queue`` at ``priority``: a new mission (ordered by :meth:`schedule` if UNORDERED),
        or into the existing mission of that priority at ``index`` (None: at its end; see
        :meth:`WaypointQueue.insert`), re-planning that mission from ``position`` (ENU metres; default
        :attr:`start`) when ``nav`` is UNORDERED. Raises IndexError for an ``index`` outside the mission, ValueError
        for more than :attr:`max_waypoints` UNORDERED waypoints, and what :meth:`order` raises."""
        fixed = nav.scheduling_type == SchedulingType.ORDERED
        if queue.mission_at(priority) is None:
            self._enqueue(queue, self.schedule(nav, position), priority, fixed=fixed)
            return
        m = queue.insert(nav.waypoints, priority, index, fixed)
        if not fixed:
            self._replan(m, position if position is not None else self.start)

    def plan_addition(self, queue: WaypointQueue, nav: AeroNavigation, index: int | None, priority: int,
                      position: Sequence[float]) -> PlannedAddition:
        """Plan adding ``nav`` at ``priority`` (``index``: as :meth:`add_to`) from ``position`` (ENU metres) on a
        copy of ``queue``: the queue is neither changed nor locked while :meth:`order` runs, so a long re-plan never
        holds the drone's control tick. Its owner commits the result (:meth:`WaypointQueue.commit`). Raises
        IndexError when ``index`` is beyond the end of that priority's mission, and what :meth:`add_to` raises."""
        twin = queue.copy()
        cur = twin.mission_at(priority)
        n = len(cur.items) if cur is not None else 0
        if index is not None and index > n:
            raise IndexError(f"index: {index} is out of range for the priority-{priority} mission of {n} items")
        self.add_to(twin, nav, index, priority, position)
        planned = twin.mission_at(priority)
        return PlannedAddition(priority, planned.copy() if planned is not None else None,
                               frozenset(id(i) for i in nav.waypoints), twin.segments_issued)

    def clear_navigation(self, priority: int | None = None) -> None:
        """Abort: drop every queued mission (or only those at ``priority``). A cleared mission never resumes. While
        a mission runs (:meth:`bind_remote`) this clears the drone's live queue."""
        if self._remote is not None:
            import ray  # lazy: heavy ray

            ray.get(self._remote.clear_navigation.remote(priority))
            return
        self.queue.remove_queued(lambda _item: True, priority)

    # ------------------------------------------------------------------ the queued navigation (:attr:`queue`)
    def remove_queued(self, drop: Callable[[Any], bool], priority: int | None = None) -> list:
        """:meth:`WaypointQueue.remove_queued` of :attr:`queue` (never forwarded to a running drone)."""
        return self.queue.remove_queued(drop, priority)

    def revise_items(self, revise: Callable[[Mission], Sequence]) -> None:
        """:meth:`WaypointQueue.revise_items` of :attr:`queue` (the pre-flight safety check)."""
        self.queue.revise_items(revise)

    def current(self, now: float) -> tuple[Mission, Any] | None:
        """:meth:`WaypointQueue.current` of :attr:`queue`: the (mission, item) to execute at sim time ``now`` (s)."""
        return self.queue.current(now)

    def complete(self, item_id: str) -> bool:
        """:meth:`WaypointQueue.complete` of :attr:`queue`."""
        return self.queue.complete(item_id)

    def discard(self, item_id: str) -> bool:
        """:meth:`WaypointQueue.discard` of :attr:`queue`."""
        return self.queue.discard(item_id)

    def pending(self, distance_driven_only: bool = False) -> int:
        """:meth:`WaypointQueue.pending` of :attr:`queue`."""
        return self.queue.pending(distance_driven_only)

    def queued(self) -> list:
        """:meth:`WaypointQueue.queued` of :attr:`queue` (every item in flying order)."""
        return self.queue.queued()

    def missions(self) -> list[Mission]:
        """:meth:`WaypointQueue.missions` of :attr:`queue` (copies, in flying order)."""
        return self.queue.missions()

    def snapshot(self) -> list[dict]:
        """:meth:`WaypointQueue.snapshot` of :attr:`queue`."""
        return self.queue.snapshot()

    @property
    def completed(self) -> list[str]:
        """Ids of the waypoints of :attr:`queue` reached (:meth:`complete`)."""
        return self.queue.completed

    @property
    def cleared(self) -> int:
        """How many times :attr:`queue` was (partly) cleared (:meth:`remove_queued`)."""
        return self.queue.cleared


    # ------------------------------------------------------------------ internals
    @staticmethod
    def _enqueue(queue: WaypointQueue, nav: AeroNavigation, priority: int, fixed: bool = False) -> None:
        queue.enqueue(nav.name, nav.waypoints, priority, nav.navigation_type.value == "DISTANCE_DRIVEN", fixed)

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
