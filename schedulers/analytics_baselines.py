"""Baseline analytics schedulers of Raj et al., FGCS 2025: the edge-only queues (FIFO, EDF, SJF, HBF, HUF) and
cloud-only (CLD), plus the Ocularone edge priority queue they all share.

Reference code: ``dream-lab/ocularone-scheduler`` — task priorities in ``ApplicationDetails/TaskCreation.java``
(algorithms 1 FIFO, 3 EDF, 4 CLD, 5 SJF, 7 HBF, 9 HUF), ordered insertion in ``Classes/PriorityQueue.java``
(``add`` with ``checkTaskDeadline=false``: edge-only baselines queue every task), and the edge executor's
dequeue rule in ``TaskScheduling/TaskExecutorEdge.java``: a task is run only if its edge time is below the time
left to its deadline, otherwise it is *expired at the edge* (never run late). The cloud executor
(``TaskExecutorLambda.java``) re-checks the expected cloud time against the time left before each execution.
"""
from __future__ import annotations

from typing import Callable, ClassVar, Iterator

from aerodaas.schedulers.analytics_base import (AnalyticsScheduler, AnalyticsTask, Decision, ModelProfile, TaskState, Workload)

__all__ = ["PriorityEdgeQueue", "EdgeFifo", "EdgeEdf", "EdgeSjf", "EdgeHbf", "EdgeHuf", "CloudOnly"]


class PriorityEdgeQueue:
    """The edge queue of the Ocularone scheduler (``Classes/PriorityQueue.java``): tasks in ascending order of a
    static priority (lower runs first), FIFO among equal priorities — a new task goes behind every queued task
    whose priority is <= its own.

    ``priority`` maps a :class:`ModelProfile` to the priority number (e.g. the relative deadline in ms for EDF);
    the value is computed once per task and kept in ``task.notes["edge_priority"]``.
    """

    def __init__(self, workload: Workload, priority: Callable[[ModelProfile], float]) -> None:
        self.w = workload
        self._priority = priority
        self.tasks: list[AnalyticsTask] = []

    def priority(self, task: AnalyticsTask) -> float:
        """The task's queue priority (lower first)."""
        if "edge_priority" not in task.notes:
            task.notes["edge_priority"] = float(self._priority(self.w[task.model]))
        return task.notes["edge_priority"]

    def edge_ms(self, task: AnalyticsTask) -> float:
        """Expected edge execution time of ``task`` in ms (its model's profile)."""
        return self.w[task.model].edge_ms

    def slot(self, task: AnalyticsTask) -> tuple[int, float]:
        """Where ``task`` would be inserted: (index, summed edge ms of the queued tasks ahead of it)."""
        prio, ahead = self.priority(task), 0.0
        for i, q in enumerate(self.tasks):
            if self.priority(q) > prio:
                return i, ahead
            ahead += self.edge_ms(q)
        return len(self.tasks), ahead

    def insert(self, task: AnalyticsTask, index: int | None = None) -> int:
        """Insert ``task`` at ``index`` (default: its priority slot); returns the index."""
        if index is None:
            index = self.slot(task)[0]
        self.tasks.insert(index, task)
        return index

    def remove(self, task: AnalyticsTask) -> None:
        """Remove ``task`` (ValueError if it is not queued)."""
        self.tasks.remove(task)

    def pop_head(self, now_ms: float) -> tuple[AnalyticsTask | None, Decision | None]:
        """Pop the head: (head, None) if it can still finish by its deadline when started now (``now + edge_ms <=
        deadline``), else (None, its EXPIRED_EDGE decision) — the reference edge executor never runs a task late.
        (None, None) when the queue is empty."""
        if not self.tasks:
            return None, None
        t = self.tasks.pop(0)
        if now_ms + self.edge_ms(t) <= t.deadline_ms:
            return t, None
        return None, Decision.drop(t, TaskState.EXPIRED_EDGE,
                                   f"edge time {self.edge_ms(t):.0f} ms exceeds the {t.deadline_ms - now_ms:.0f} ms "
                                   "left when it reached the head of the edge queue")

    def pop_runnable(self, now_ms: float) -> tuple[AnalyticsTask | None, list[Decision]]:
        """Pop heads until one can still finish by its deadline (see :meth:`pop_head`); returns it (or None) and
        the EXPIRED_EDGE decisions of the heads expired on the way."""
        drops = []
        while self.tasks:
            t, d = self.pop_head(now_ms)
            if t is not None:
                return t, drops
            drops.append(d)
        return None, drops

    def first_violation(self, start_ms: float) -> AnalyticsTask | None:
        """The first queued task that would miss its deadline if the queue ran in order from ``start_ms``
        (``PriorityQueue.scanForDeadlineViolation``), or None."""
        t = start_ms
        for q in self.tasks:
            t += self.edge_ms(q)
            if t > q.deadline_ms:
                return q
        return None

    def __len__(self) -> int:
        return len(self.tasks)

    def __iter__(self) -> Iterator[AnalyticsTask]:
        return iter(self.tasks)


# --------------------------------------------------------------------------------------------- edge-only
class _EdgeOnly(AnalyticsScheduler):
    """Edge-only baseline: every task joins one priority-ordered edge queue (no admission check); the edge runs
    the head if it can still finish by its deadline, otherwise the head is expired (EXPIRED_EDGE). Subclasses set
    :meth:`priority`."""

    uses_cloud = False

    @staticmethod
    def priority(p: ModelProfile) -> float:
        """Queue priority of a task of model ``p`` (lower first)."""
        return 0.0

    def __init__(self, workload: Workload) -> None:
        super().__init__(workload)
        self.queue = PriorityEdgeQueue(workload, self.priority)

    def submit(self, task: AnalyticsTask, now_ms: float) -> list[Decision]:
        self.queue.insert(task)
        return []

    def _pop_edge(self, now_ms: float) -> tuple[AnalyticsTask | None, list[Decision]]:
        return self.queue.pop_runnable(now_ms)

    def held_tasks(self) -> list[AnalyticsTask]:
        return list(self.queue)


class EdgeFifo(_EdgeOnly):
    """EDGE_FIFO (algorithm 1): one edge queue in arrival order."""

    name = "EDGE_FIFO"


class EdgeEdf(_EdgeOnly):
    """EDGE_EDF (algorithm 3): priority = the model's relative deadline (ms), ties FIFO — as in the reference,
    the *relative* deadline, so a later task of a tighter model overtakes earlier tasks of looser models."""

    name, priority = "EDGE_EDF", staticmethod(lambda p: p.deadline_ms)


class EdgeSjf(_EdgeOnly):
    """EDGE_SJF (algorithm 5): shortest expected edge time first, ties FIFO."""

    name, priority = "EDGE_SJF", staticmethod(lambda p: p.edge_ms)


class EdgeHbf(_EdgeOnly):
    """EDGE_HBF (algorithm 7): highest benefit first, ties FIFO."""

    name, priority = "EDGE_HBF", staticmethod(lambda p: -p.benefit)


class EdgeHuf(_EdgeOnly):
    """EDGE_HUF (algorithm 9): highest edge utility (benefit - edge cost) first, ties FIFO."""

    name, priority = "EDGE_HUF", staticmethod(lambda p: -p.edge_utility)


# --------------------------------------------------------------------------------------------- cloud-only
class CloudOnly(AnalyticsScheduler):
    """CLOUD (algorithm 4, "CLD"): every task goes to the cloud at once if its cloud utility is positive, else it
    is dropped for cost. The cloud executor's re-check (base :meth:`cloud_admit`) applies, as in the reference.

    Failover (ours; the reference has no cloud loss): while no cloud executor is reachable
    (:meth:`on_cloud_availability`), new tasks join an edge FIFO queue instead — run if they can still finish by
    their deadline when they reach the head, else expired — so a mission keeps its analytics when the cloud node
    is lost. Queued tasks drain on the edge after the cloud returns; new ones go to the cloud again."""

    name = "CLOUD"
    uses_cloud: ClassVar[bool] = True

    def __init__(self, workload: Workload) -> None:
        super().__init__(workload)
        self.fallback = PriorityEdgeQueue(workload, lambda p: 0.0)

    def submit(self, task: AnalyticsTask, now_ms: float) -> list[Decision]:
        p = self.w[task.model]
        if p.cloud_utility <= 0:
            return [Decision.drop(task, TaskState.DROPPED_COST, f"cloud utility {p.cloud_utility:g} <= 0")]
        if not self.cloud_available:
            self.fallback.insert(task)
            return []
        return [Decision.cloud(task, "cloud only")]

    def _pop_edge(self, now_ms: float) -> tuple[AnalyticsTask | None, list[Decision]]:
        return self.fallback.pop_runnable(now_ms)

    def held_tasks(self) -> list[AnalyticsTask]:
        return list(self.fallback)
