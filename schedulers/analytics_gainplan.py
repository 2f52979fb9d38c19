"""GAINPLAN: our edge/cloud analytics scheduler — a rolling *max-gain edge plan* with just-in-time cloud
commitment.

Idea. On one edge accelerator beside a cloud, the cloud can already run every task whose cloud utility is
positive in time; the edge is worth using only for its *gain* over that fallback, ``(benefit - edge cost) -
max(0, benefit - cloud cost)`` (the full edge utility for a task with no usable cloud option). DEMS places
tasks on the edge in EDF order of their model's relative deadline and evicts only tasks *behind* the new one,
so the edge fills with short, tight-deadline, low-gain models while the high-gain ones (long models whose
cloud cost nearly eats their benefit) go to the cloud. GAINPLAN instead keeps every undecided task in one pool
and, at each decision point, selects the subset of tasks the edge should run as an exact weighted
deadline-scheduling problem: maximise the summed gain of a set of tasks that all meet their deadlines when
run back to back from the moment the edge is free. With all candidates available now this is
1 || sum w_j U_j, solved exactly by Lawler & Moore's dynamic program over tasks in earliest-due-date order
(E. L. Lawler, J. M. Moore, "A functional equation and its application to resource allocation and sequencing
problems", Management Science 16(1), 1969) — here with sparse Pareto states (finish time, gain) instead of a
time grid. EDD order is optimal for feasibility of a chosen set (Jackson's rule), so the edge runs the plan's
first task. This is a fractional-knapsack view made exact and deadline-aware: edge milliseconds go to the
models with the highest gain per edge-ms that still fit.

Cloud use follows DEMS's just-in-time idea (Raj et al., FGCS 2025): a task with a cloud option stays a
candidate for the edge until its cloud trigger (deadline - cloud estimate - 10 ms, acted on 50 ms early).
Then it is *committed* to the edge if the current max-gain plan starts it soon — within the shortest model edge
time of the edge becoming free while the offered edge load (last 5 s of arrivals) exceeds the edge's capacity, at
any point of the plan otherwise — and its weight becomes its full edge utility (leaving the plan would now lose
it); else it is released to the cloud (a task planned further out would likely be displaced by better arrivals). Tasks without a cloud option
(non-positive cloud utility, or too late for the cloud) stay candidates until they no longer fit on the edge,
and are then dropped (for cost or time). The cloud-latency estimate is the largest of the last 5 completed
cloud round trips (:class:`PessimisticLatencyEstimator`), not DEMS-A's window mean. Nothing here is specific to a model name: gains, times and deadlines come from the workload.

Decision points: :meth:`submit` (drops hopeless tasks), :meth:`poll` (triggers), :meth:`next_edge_task` (the
plan's first task). A task is never started on the edge unless it can finish by its deadline at the profile's
edge time.
"""
from __future__ import annotations

from collections import deque

from aerodaas.schedulers.analytics_base import (EXECUTED_STATES, AnalyticsScheduler, AnalyticsTask, Decision, TaskState, Workload)
from aerodaas.schedulers.analytics_dems import CLOUD_TRIGGER_BUFFER_MS, JIT_EARLY_MS, JIT_LATE_MS
from aerodaas.schedulers.analytics_estimators import RecentMaxEstimator, make_estimator

__all__ = ["GainPlan", "max_gain_edge_plan", "PessimisticLatencyEstimator"]

OPEN, COMMITTED, EDGE_ONLY = "open", "committed", "edge_only"


def max_gain_edge_plan(items: list[tuple[float, float, float]], start_ms: float) -> list[int]:
    """Exact max-weight on-time subset for one machine, all jobs available at ``start_ms`` (Lawler & Moore 1969).

    ``items``: (deadline_ms, processing_ms, gain) per job. Returns the indices of the chosen jobs in
    earliest-deadline order (run them in that order from ``start_ms``: every one finishes by its deadline).
    Jobs with gain <= 0 are never chosen; ties prefer the plan that frees the machine earliest.
    """
    order = sorted(range(len(items)), key=lambda i: (items[i][0], i))
    states: list[tuple[float, float, tuple[int, ...]]] = [(start_ms, 0.0, ())]
    for i in order:
        deadline, proc, gain = items[i]
        if gain <= 0:
            continue
        grown = [(f + proc, g + gain, ch + (i,)) for f, g, ch in states if f + proc <= deadline]
        if not grown:
            continue
        merged = sorted(states + grown, key=lambda s: (s[0], -s[1]))
        states, best = [], float("-inf")
        for s in merged:  # Pareto front: later finish only if strictly more gain
            if s[1] > best + 1e-9:
                states.append(s)
                best = s[1]
    return list(max(states, key=lambda s: (s[1], -s[0]))[2])


#: GAINPLAN's default estimate: the largest of the last 5 observed round trips (see :mod:`.analytics_estimators`)
PessimisticLatencyEstimator = RecentMaxEstimator


class GainPlan(AnalyticsScheduler):
    """GAINPLAN — rolling max-gain edge plan with just-in-time cloud commitment (see the module docstring).

    Every held task is in :attr:`pool` with ``task.notes["mode"]``: ``"open"`` (cloud option alive, trigger
    :meth:`trigger_ms` from the current estimate), ``"committed"`` (to the edge) or ``"edge_only"`` (no cloud
    option). ``commit_horizon_ms`` (default: the shortest model edge time) and ``latency_window`` (default 5) tune
    the commitment rule and the latency estimate; ``estimator`` (a spec of :func:`~.analytics_estimators.make_estimator`)
    replaces the estimate (the fair-margin option); ValueError if negative / < 1 / a bad spec. Terminal
    states: done on the edge or the cloud; DROPPED_COST / DROPPED_TIME when a task without a cloud option no
    longer fits on the edge (cost if its cloud utility is <= 0); EXPIRED_EDGE for a committed task that no
    longer fits.
    """

    name = "GAINPLAN"
    options = ("estimator", "commit_horizon_ms", "latency_window")
    #: a held task is decided this many ms before its cloud trigger (DEMS's JIT queue: 50)
    jit_early_ms: float = JIT_EARLY_MS

    def __init__(self, workload: Workload, *, commit_horizon_ms: float | None = None, latency_window: int = 5,
                 estimator: str | None = None) -> None:
        super().__init__(workload)
        #: commit a task to the edge at its cloud trigger only if the plan starts it within this many ms of the
        #: edge becoming free (default: the shortest model edge time)
        self.commit_horizon_ms = workload.min_edge_ms if commit_horizon_ms is None else float(commit_horizon_ms)
        if self.commit_horizon_ms < 0:
            raise ValueError(f"commit_horizon_ms must be >= 0, got {commit_horizon_ms!r}")
        self.latency = (make_estimator(estimator, workload) if estimator
                        else RecentMaxEstimator(workload, window=latency_window))
        self.pool: list[AnalyticsTask] = []
        #: (arrival ms, edge ms) of recent arrivals, for the offered edge load
        self._recent: deque[tuple[float, float]] = deque()
        self._first_arrival: float | None = None
        self.load_window_ms = 5_000.0
        self._now = 0.0  # time of the current decision point (ms)

    # -- estimates
    def cloud_estimate_ms(self, model: str) -> float:
        return self.latency.value(self.w[model].name)

    def gain(self, task: AnalyticsTask) -> float:
        """Utility gained by running ``task`` on the edge rather than its fallback."""
        p = self.w[task.model]
        return p.edge_utility - (p.cloud_utility if task.notes.get("mode") == OPEN else 0.0)

    def _plan(self, start_ms: float) -> list[AnalyticsTask]:
        cands = [t for t in self.pool if start_ms + self.w[t.model].edge_ms <= t.deadline_ms]
        chosen = max_gain_edge_plan([(t.deadline_ms, self.w[t.model].edge_ms, self.gain(t)) for t in cands], start_ms)
        return [cands[i] for i in chosen]

    def _edge_free_at(self, now_ms: float) -> float:
        return max(now_ms, self.edge_busy_until_ms) if self.edge_running is not None else now_ms

    # -- helpers
    def _lose(self, task: AnalyticsTask, now_ms: float, why: str) -> Decision:
        """Terminal drop of a pool task that can no longer run anywhere."""
        self.pool.remove(task)
        if task.notes.get("mode") == COMMITTED:
            return Decision.drop(task, TaskState.EXPIRED_EDGE, f"committed to the edge but no longer fits: {why}")
        p = self.w[task.model]
        state = TaskState.DROPPED_COST if p.cloud_utility <= 0 else TaskState.DROPPED_TIME
        return Decision.drop(task, state, why)

    def _sweep(self, now_ms: float) -> list[Decision]:
        """Drop held tasks without a cloud option that no longer fit on the edge."""
        start = self._edge_free_at(now_ms)
        return [self._lose(t, now_ms, f"edge time {self.w[t.model].edge_ms:.0f} ms no longer fits before the deadline")
                for t in list(self.pool)
                if t.notes.get("mode") != OPEN and start + self.w[t.model].edge_ms > t.deadline_ms]

    # -- the contract
    def trigger_ms(self, task: AnalyticsTask) -> float:
        """Cloud trigger of a held task from the *current* latency estimate: deadline - estimate - 10 ms."""
        return task.deadline_ms - self.cloud_estimate_ms(task.model) - CLOUD_TRIGGER_BUFFER_MS

    def offered_load(self, now_ms: float) -> float:
        """Edge time requested per ms by the tasks that arrived in the last ``load_window_ms`` (1.0 = the edge
        would be busy all the time running every one of them): their edge ms over the window's length (over the
        time since the first arrival while the run is younger; at least a fifth of the window). Until 2026-11-22
        the divisor was the time since the oldest arrival *in* the window, up to a frame period short of it: 3
        drones at LIGHT (948 ms/s) read as > 1, so GAINPLAN/EVPLAN committed only imminent tasks and sent ~590
        more per run to the cloud (EVPLAN 1 % below GEMS)."""
        if self._first_arrival is None:
            return 0.0
        while self._recent and self._recent[0][0] <= now_ms - self.load_window_ms:  # window (now - W, now]
            self._recent.popleft()
        span = max(min(self.load_window_ms, now_ms - self._first_arrival), self.load_window_ms / 5)
        return sum(e for _, e in self._recent) / span

    def submit(self, task: AnalyticsTask, now_ms: float) -> list[Decision]:
        p = self.w[task.model]
        self.pool.append(task)
        self._recent.append((now_ms, p.edge_ms))
        if self._first_arrival is None:
            self._first_arrival = now_ms
        if p.cloud_utility > 0 and self.cloud_available and now_ms + self.cloud_estimate_ms(task.model) <= task.deadline_ms:
            task.notes["mode"] = OPEN
            return self.poll(now_ms) if self.trigger_ms(task) - now_ms <= self.jit_early_ms else []
        task.notes["mode"] = EDGE_ONLY
        if p.edge_utility <= 0 or now_ms + p.edge_ms > task.deadline_ms:
            return [self._lose(task, now_ms, "no usable cloud option and no gain from (or time for) the edge")]
        return []

    def _planned_start(self, task: AnalyticsTask, now_ms: float) -> float | None:
        """When the current max-gain plan would start ``task`` on the edge (None if it is not in the plan)."""
        start = self._edge_free_at(now_ms)
        for q in self._plan(start):
            if q is task:
                return start
            start += self.w[q.model].edge_ms
        return None

    def _cloud_option_gone(self, task: AnalyticsTask, now_ms: float) -> bool:
        """At its trigger: has ``task`` lost its cloud option (trigger more than 10 ms past, or no cloud)?"""
        return self.trigger_ms(task) - now_ms < -JIT_LATE_MS or not self.cloud_available

    def _admit_cloud_ms(self, task: AnalyticsTask, now_ms: float) -> float:
        """The cloud time the re-check (:meth:`cloud_admit`) holds a released task to (ms)."""
        return self.cloud_estimate_ms(task.model)

    def poll(self, now_ms: float) -> list[Decision]:
        self._now = now_ms
        out = self._sweep(now_ms)
        due = sorted((t for t in self.pool if t.notes.get("mode") == OPEN and self.trigger_ms(t) - now_ms <= self.jit_early_ms),
                     key=self.trigger_ms)
        for t in due:
            if self._cloud_option_gone(t, now_ms):
                t.notes["mode"] = EDGE_ONLY  # the cloud option is gone; an edge candidate until it no longer fits
                self.counters["cloud_option_lost"] += 1
                continue
            start = self._planned_start(t, now_ms)
            horizon = self.commit_horizon_ms if self.offered_load(now_ms) > 1.0 else float("inf")
            if start is not None and start - self._edge_free_at(now_ms) <= horizon:
                t.notes["mode"] = COMMITTED
                self.counters["committed_to_edge"] += 1
            else:
                out.append(self._release_to_cloud(t, now_ms, "at its cloud trigger: not about to run on the edge"))
        return out

    def _release_to_cloud(self, t: AnalyticsTask, now_ms: float, why: str) -> Decision:
        """Take ``t`` out of the pool and send it to the cloud (its admit-by time computed now)."""
        self.pool.remove(t)
        self.counters["released_to_cloud"] += 1
        t.notes["cloud_ms"] = self._admit_cloud_ms(t, now_ms)
        return Decision.cloud(t, why)

    def next_poll_ms(self) -> float | None:
        triggers = [self.trigger_ms(t) for t in self.pool if t.notes.get("mode") == OPEN]
        return min(triggers) - self.jit_early_ms if triggers else None

    def _pop_edge(self, now_ms: float) -> tuple[AnalyticsTask | None, list[Decision]]:
        drops = self._sweep(now_ms)
        plan = self._plan(now_ms)
        if not plan:
            return None, drops
        self.pool.remove(plan[0])
        return plan[0], drops

    def on_cloud_done(self, task: AnalyticsTask, now_ms: float, latency_ms: float) -> list[Decision]:
        if task.state in EXECUTED_STATES:  # a refused or failed task's reply time is no cloud round trip
            self.latency.observe(task.model, latency_ms)
        return []

    def on_cloud_availability(self, available: bool, now_ms: float) -> list[Decision]:
        """Without a cloud, open tasks lose their cloud option and stay edge candidates (dropped when they no
        longer fit)."""
        super().on_cloud_availability(available, now_ms)
        if not available:
            for t in self.pool:
                if t.notes.get("mode") == OPEN:
                    t.notes["mode"] = EDGE_ONLY
        return self._sweep(now_ms)

    def held_tasks(self) -> list[AnalyticsTask]:
        return list(self.pool)
