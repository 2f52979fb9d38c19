"""Baseline analytics schedulers (Raj et al., FGCS 2025, §baselines): edge-only queues and cloud-only."""
from __future__ import annotations

from collections import deque

from .analytics_base import AnalyticsScheduler, AnalyticsTask, Decision, TaskState, register_analytics_scheduler


@register_analytics_scheduler
class EdgeFifo(AnalyticsScheduler):
    """EDGE_FIFO: every task joins one edge queue in arrival order; the edge runs the head. A task whose deadline
    has already passed when it reaches the head is not run (EXPIRED_EDGE)."""

    name = "EDGE_FIFO"
    uses_cloud = False

    def __init__(self, workload) -> None:
        super().__init__(workload)
        self.queue: deque[AnalyticsTask] = deque()

    def submit(self, task: AnalyticsTask, now_ms: float) -> list[Decision]:
        self.queue.append(task)
        return []

    def _pop_edge(self, now_ms: float) -> tuple[AnalyticsTask | None, list[Decision]]:
        drops = []
        while self.queue:
            t = self.queue.popleft()
            if now_ms >= t.deadline_ms:
                drops.append(Decision.drop(t, TaskState.EXPIRED_EDGE, "deadline passed while queued at the edge"))
                continue
            return t, drops
        return None, drops

    def held_tasks(self) -> list[AnalyticsTask]:
        return list(self.queue)


@register_analytics_scheduler
class CloudOnly(AnalyticsScheduler):
    """CLOUD: every task goes to the cloud at once if its cloud utility is positive (else dropped for cost)."""

    name = "CLOUD"

    def submit(self, task: AnalyticsTask, now_ms: float) -> list[Decision]:
        p = self.w[task.model]
        if p.cloud_utility <= 0:
            return [Decision.drop(task, TaskState.DROPPED_COST, f"cloud utility {p.cloud_utility:g} <= 0")]
        if not self.cloud_available:
            return [Decision.drop(task, TaskState.DROPPED_TIME, "cloud unavailable")]
        return [Decision.cloud(task, "cloud only")]

    def _pop_edge(self, now_ms: float) -> tuple[AnalyticsTask | None, list[Decision]]:
        return None, []

    def cloud_admit(self, task: AnalyticsTask, now_ms: float) -> bool:
        return True

    def held_tasks(self) -> list[AnalyticsTask]:
        return []
