"""Deadline-driven edge+cloud schedulers of Raj, Mittal, Gupta, Simmhan, "Adaptive heuristics for scheduling DNN
inferencing on edge and cloud for personalized UAV fleets", FGCS 2025 (arXiv 2412.20860): E+C, DEM, DEMS, DEMS-A
and GEMS, as pure policies on the :class:`~.analytics_base.AnalyticsScheduler` contract.

Rules follow the published code ``dream-lab/ocularone-scheduler`` (algorithm numbers 62 E+C, 52 DEM, 31 DEMS,
91 DEMS-A, 35 GEMS): ``Classes/PriorityQueue.java`` (insertion with deadline check and score-based eviction,
``peekAndPoll`` JIT window, ``scanForDeadlineViolation``, ``scanOnProfitAndReturnPriorityQueue``),
``TaskScheduling/Scheduler.java`` and ``Rescheduler.java`` (what happens to rejected and evicted tasks, DEMS-A
cool-down), ``TentativeCloudQueueWorker.java`` (JIT release), ``TaskExecutorEdge.java`` (work stealing, expiry at
the head), ``ApplicationDetails/Application.java`` (``calculateScore``, ``getUtilityDiff``, constants: 10-entry
latency window, 10 ms drift threshold, 10 s cool-down, 20 s gatekeeper window, 0.9 required fraction),
``PostProcessing.java`` / ``TriggerUpdate.java`` (latency window) and ``GateKeeper.java``. Our own code; the
deviations are listed in ``docs/analytics-scheduler-rules.md``.

Edge queue order for all of them is EDF by the model's *relative* deadline, ties FIFO (TaskCreation.java).
Throughout, a task "fits" on the edge from time ``t`` if ``t + edge_ms <= deadline`` and on the cloud if
``t + cloud_ms <= deadline`` (the reference mixes ``<`` and ``<=``; the difference is one millisecond).
"""
from __future__ import annotations

import bisect
import itertools
from collections import Counter, deque
from dataclasses import dataclass, field
from typing import ClassVar

from aerodaas.schedulers.analytics_base import (EXECUTED_STATES, AnalyticsScheduler, AnalyticsTask, Decision, ModelProfile, TaskState,
                             Workload)
from aerodaas.schedulers.analytics_baselines import PriorityEdgeQueue
from aerodaas.schedulers.analytics_estimators import LatencyEstimator, WindowMeanEstimator, make_estimator

__all__ = ["EdgeCloud", "Dem", "Dems", "DemsA", "Gems", "TentativeCloudQueue", "CloudLatencyEstimator",
           "EVICTION_SCANS", "EDGE_TRIGGER_BUFFER_MS", "CLOUD_TRIGGER_BUFFER_MS", "JIT_EARLY_MS", "JIT_LATE_MS"]

#: edge trigger = deadline - edge_ms - this (TaskCreation.edgeBuffer)
EDGE_TRIGGER_BUFFER_MS = 10.0
#: cloud trigger = deadline - cloud_ms - this (TaskCreation.cloudBuffer)
CLOUD_TRIGGER_BUFFER_MS = 10.0
#: a held task is released when its trigger is at most this far ahead (PriorityQueue.bufferForTentativeCloud)
JIT_EARLY_MS = 50.0
#: ... and dropped when its trigger passed by more than this (PriorityQueue.peekAndPoll)
JIT_LATE_MS = 10.0


def edf_priority(p: ModelProfile) -> float:
    """EDF queue priority of the reference: the model's relative deadline in ms (lower first)."""
    return p.deadline_ms


def task_on_time(task: AnalyticsTask, now_ms: float) -> bool:
    """Whether a task reported at ``now_ms`` counts as on time: once the dispatcher has set a terminal state, only
    DONE_ON_TIME does (a task refused by the cloud re-check, failed or dropped never met its deadline); a task
    still PENDING (a harness that reports before setting the state) counts if ``now_ms <= deadline``."""
    if task.state is not TaskState.PENDING:
        return task.state is TaskState.DONE_ON_TIME
    return now_ms <= task.deadline_ms


# --------------------------------------------------------------------------------------------- tentative queue
@dataclass(order=True)
class _Held:
    key: float
    seq: int
    task: AnalyticsTask = field(compare=False)
    kind: str = field(compare=False)  # "cloud": JIT release to the cloud; "cost": work-stealing candidate only


class TentativeCloudQueue:
    """DEMS's tentative cloud queue: held tasks ordered by a trigger time (ms), FIFO among equal triggers.

    Two kinds of entries share it, as in the reference: ``"cloud"`` tasks keyed by their *cloud* trigger
    (deadline - cloud_ms - 10), released to the cloud just in time; and ``"cost"`` tasks (cloud utility <= 0)
    keyed by their *edge* trigger (deadline - edge_ms - 10), kept only as work-stealing candidates.
    """

    def __init__(self) -> None:
        self._items: list[_Held] = []
        self._seq = itertools.count()

    def add(self, task: AnalyticsTask, key_ms: float, kind: str) -> None:
        if kind not in ("cloud", "cost"):
            raise ValueError(f"kind must be 'cloud' or 'cost', got {kind!r}")
        task.notes["trigger_ms"] = key_ms
        bisect.insort(self._items, _Held(key_ms, next(self._seq), task, kind))

    def head(self) -> _Held | None:
        return self._items[0] if self._items else None

    def pop_head(self) -> _Held:
        return self._items.pop(0)

    def remove(self, held: _Held) -> None:
        self._items.remove(held)

    def entries(self) -> list[_Held]:
        return list(self._items)

    def tasks(self) -> list[AnalyticsTask]:
        return [h.task for h in self._items]

    def __len__(self) -> int:
        return len(self._items)


# --------------------------------------------------------------------------------------------- latency estimate
#: DEMS-A's per-model estimate (window of 10, 10 ms drift); see :mod:`.analytics_estimators`
CloudLatencyEstimator = WindowMeanEstimator

#: how the eviction scan treats the queued tasks behind the insertion point (see :class:`EdgeCloud`)
EVICTION_SCANS = ("reference", "full")


# --------------------------------------------------------------------------------------------- E+C
class EdgeCloud(AnalyticsScheduler):
    """E+C (algorithm 62): a new task is inserted at its EDF slot if the edge backlog ahead of it (remaining time
    of the running task + edge times of the queued tasks ahead) plus its own edge time meets its deadline —
    *without* checking the tasks behind it, which are never evicted (they may later expire at the head).
    Otherwise it goes to the cloud at once if its cloud utility is positive and its cloud time fits (else it is
    dropped for cost / time). The edge runs the head if it still fits, else expires it."""

    name = "E+C"
    #: evict tasks behind the insertion point that would miss (DEM and later)
    evict: ClassVar[bool] = False
    options = ("eviction_scan", "estimator")

    def __init__(self, workload: Workload, *, eviction_scan: str = "reference", estimator: str | None = None) -> None:
        """``eviction_scan``: ``"reference"`` (default) checks the queued tasks behind the insertion point exactly as
        ``PriorityQueue.add`` does — the first of them was already consumed by the outer iterator, so it is neither
        checked nor counted in the running finish time; ``"full"`` checks every one (our earlier variant,
        deviation 2 in docs/analytics-scheduler-rules.md). ``estimator``: a cloud-latency estimator spec
        (:func:`~.analytics_estimators.make_estimator`) replacing the policy's own (the fair-margin option).
        Raises ValueError for an unknown scan or a bad spec."""
        super().__init__(workload)
        if eviction_scan not in EVICTION_SCANS:
            raise ValueError(f"eviction_scan must be one of {EVICTION_SCANS}, got {eviction_scan!r}")
        self.eviction_scan = eviction_scan
        self.latency: LatencyEstimator | None = (make_estimator(estimator, workload) if estimator
                                                 else self._default_estimator(workload))
        self.queue = PriorityEdgeQueue(workload, edf_priority)

    def _default_estimator(self, workload: Workload) -> LatencyEstimator | None:
        """The policy's own cloud-latency estimator (None: the profile's ``cloud_ms``)."""
        return None

    def cloud_estimate_ms(self, model: str) -> float:
        return self.latency.value(model) if self.latency is not None else self.w[model].cloud_ms

    # -- hooks for subclasses
    def _observe_terminal(self, task: AnalyticsTask, now_ms: float, on_time: bool) -> None:
        """A task reached a terminal state (GEMS counts these)."""

    def _settle(self, decisions: list[Decision], now_ms: float) -> list[Decision]:
        """Every decision list passes here before it is returned; drops are terminal."""
        for d in decisions:
            if d.kind == "drop":
                self._observe_terminal(d.task, now_ms, False)
        return decisions

    def _off_edge(self, task: AnalyticsTask, now_ms: float, why: str) -> list[Decision]:
        """Place a task the edge queue rejected or evicted."""
        return [self._cloud_or_drop(task, now_ms, why)]

    # -- scoring and admission
    def edge_backlog_ms(self, now_ms: float) -> float:
        """Remaining expected time of the running edge task (0 when idle)."""
        return max(0.0, self.edge_busy_until_ms - now_ms) if self.edge_running is not None else 0.0

    def score(self, task: AnalyticsTask, now_ms: float) -> float:
        """Eviction score (Application.calculateScore): |cloud cost - edge cost| if the task can still finish on the
        cloud with positive cloud utility, else |benefit - edge cost| (what is lost if it leaves the edge)."""
        p = self.w[task.model]
        if p.cloud_utility > 0 and self.cloud_available and now_ms + self.cloud_estimate_ms(task.model) <= task.deadline_ms:
            return abs(p.cloud_cost - p.edge_cost)
        return abs(p.benefit - p.edge_cost)

    def _admit(self, task: AnalyticsTask, now_ms: float) -> tuple[bool, list[AnalyticsTask], str]:
        """Try to insert ``task`` at its EDF slot (PriorityQueue.add). Returns (inserted, evicted tasks, reason if
        not inserted)."""
        idx, ahead = self.queue.slot(task)
        edge_ms = self.queue.edge_ms(task)
        finish = now_ms + self.edge_backlog_ms(now_ms) + ahead + edge_ms
        if finish > task.deadline_ms:
            return False, [], (f"edge backlog {finish - now_ms - edge_ms:.0f} ms + edge {edge_ms:.0f} ms exceeds the "
                               f"{task.deadline_ms - now_ms:.0f} ms left")
        victims: list[AnalyticsTask] = []
        if self.evict:
            lost = 0.0
            behind = self.queue.tasks[idx:]
            if self.eviction_scan == "reference":  # PriorityQueue.add: the outer iterator consumed the first one
                behind = behind[1:]
            for q in behind:
                q_end = finish + self.queue.edge_ms(q)
                if q_end > q.deadline_ms:
                    victims.append(q)
                    lost += self.score(q, now_ms)
                else:
                    finish = q_end
            gain = self.score(task, now_ms)
            if victims and not lost < gain:
                self.counters["eviction_refused"] += 1
                return False, [], (f"inserting it would make {len(victims)} queued task(s) miss, whose score {lost:g} "
                                   f">= its score {gain:g}")
            for v in victims:
                self.queue.remove(v)
        self.queue.insert(task, self.queue.slot(task)[0])
        return True, victims, ""

    # -- the contract
    def submit(self, task: AnalyticsTask, now_ms: float) -> list[Decision]:
        inserted, victims, why = self._admit(task, now_ms)
        self.counters["admitted" if inserted else "rejected"] += 1
        self.counters["evicted"] += len(victims)
        out = [] if inserted else self._off_edge(task, now_ms, f"rejected by the edge queue: {why}")
        for v in victims:
            out += self._off_edge(v, now_ms, f"evicted from the edge queue by task #{task.task_id} ({task.model})")
        return self._settle(out, now_ms)

    def _pop_edge(self, now_ms: float) -> tuple[AnalyticsTask | None, list[Decision]]:
        task, drops = self.queue.pop_runnable(now_ms)
        return task, self._settle(drops, now_ms)

    def on_edge_done(self, task: AnalyticsTask, now_ms: float, exec_ms: float) -> list[Decision]:
        super().on_edge_done(task, now_ms, exec_ms)
        self._observe_terminal(task, now_ms, task_on_time(task, now_ms))
        return self._settle([], now_ms)

    def on_cloud_done(self, task: AnalyticsTask, now_ms: float, latency_ms: float) -> list[Decision]:
        """Every task this policy sent to the cloud ends here once (done, late, refused by the re-check — before
        sending or at the executor — or failed): counted as a terminal event (GEMS), on time only if DONE_ON_TIME.
        The re-check itself (:meth:`cloud_admit`, the base class's) is a pure query: the dispatcher calls it many
        times per task to find the admit-by time."""
        if self.latency is not None and task.state in EXECUTED_STATES:  # only completions feed the estimate
            self.latency.observe(task.model, latency_ms)
        self._observe_terminal(task, now_ms, task_on_time(task, now_ms))
        return self._settle([], now_ms)

    def held_tasks(self) -> list[AnalyticsTask]:
        return list(self.queue)


# --------------------------------------------------------------------------------------------- DEM
class Dem(EdgeCloud):
    """DEM (algorithm 52): E+C plus *migration*: when a new task is inserted, the queued tasks behind it that
    would now miss their deadline are evicted — only if their summed :meth:`score` is lower than the new task's
    (otherwise the new task is rejected). Rejected and evicted tasks go to the cloud at once (no tentative
    queue, no work stealing, no retention of tasks with non-positive cloud utility)."""

    name = "DEM"
    evict = True


# --------------------------------------------------------------------------------------------- DEMS
class Dems(Dem):
    """DEMS (algorithm 31): DEM plus a tentative cloud queue with just-in-time release and work stealing.

    1. Admission: as :class:`Dem` (EDF slot + deadline check + score-based eviction).
    2. A rejected or evicted task: if benefit - cloud cost <= 0 it is *dropped for cost but kept as a
       work-stealing candidate* (held keyed by its edge trigger = deadline - edge_ms - 10); else if its cloud
       time exceeds the time left it is dropped for time; else it is held in the tentative cloud queue keyed by
       its cloud trigger = deadline - cloud_ms - 10.
    3. JIT release (:meth:`poll`, due at trigger - 50): a held cloud task whose trigger is within [-10, +50] ms
       of now goes to the cloud; one more than 10 ms past its trigger is dropped for time. A cost candidate whose
       edge trigger comes within 50 ms is dropped for cost — so every such task reaches exactly one terminal
       state: it runs on the edge if stolen (done on time/late), otherwise DROPPED_COST when it expires unstolen.
    4. Work stealing (:meth:`_pop_edge`): with the edge queue empty, the edge runs the best-ranked held task that
       still fits its own deadline; with tasks queued, if the head's slack (its edge trigger - now) exceeds the
       shortest model edge time, it runs the best-ranked held task whose edge time is below that slack and that
       makes no queued task miss. Rank = (cloud cost - edge cost) * 1000 / edge_ms, +1000 for negative cloud
       utility (Application.getUtilityDiff); ties by trigger.
    5. The cloud re-checks the deadline (:meth:`cloud_admit`) before executing.

    While the cloud is unavailable, held cloud tasks stay work-stealing candidates until their trigger, when
    they are dropped for time if it is still unavailable.
    """

    name = "DEMS"
    #: steal when the edge queue is empty (the reference does this for DEMS and DEMS-A)
    steal_when_idle: ClassVar[bool] = True

    def __init__(self, workload: Workload, **options) -> None:
        super().__init__(workload, **options)
        self.tentative = TentativeCloudQueue()
        #: steal into a busy queue only if the head's slack exceeds this (ms): the workload's shortest edge time
        #: (the reference hard-codes 132 ms; deviation 5)
        self.steal_slack_ms = workload.min_edge_ms

    # -- placing rejected/evicted tasks
    def _off_edge(self, task: AnalyticsTask, now_ms: float, why: str) -> list[Decision]:
        p = self.w[task.model]
        if p.cloud_utility <= 0:
            key = task.deadline_ms - p.edge_ms - EDGE_TRIGGER_BUFFER_MS
            if key - now_ms <= JIT_EARLY_MS:
                return [Decision.drop(task, TaskState.DROPPED_COST,
                                      f"{why}; cloud utility {p.cloud_utility:g} <= 0 and too late to steal")]
            task.notes["held_for"] = "cost"
            self.tentative.add(task, key, "cost")
            return []
        est = self.cloud_estimate_ms(task.model)
        if now_ms + est > task.deadline_ms:
            return self._cloud_too_slow(task, now_ms, est, why)
        return self._hold_for_cloud(task, now_ms, est, why)

    def _cloud_too_slow(self, task: AnalyticsTask, now_ms: float, est_ms: float, why: str) -> list[Decision]:
        return [Decision.drop(task, TaskState.DROPPED_TIME,
                              f"{why}; cloud time {est_ms:.0f} ms exceeds the {task.deadline_ms - now_ms:.0f} ms left")]

    def _hold_for_cloud(self, task: AnalyticsTask, now_ms: float, est_ms: float, why: str) -> list[Decision]:
        task.notes["cloud_ms"] = est_ms
        task.notes["held_for"] = "cloud"
        key = task.deadline_ms - est_ms - CLOUD_TRIGGER_BUFFER_MS
        if key - now_ms <= JIT_EARLY_MS:  # already inside the JIT window: release now
            return [self._release(task, now_ms, f"{why}; released to the cloud at once (trigger in {key - now_ms:.0f} ms)")]
        self.tentative.add(task, key, "cloud")
        return []

    def _release(self, task: AnalyticsTask, now_ms: float, why: str) -> Decision:
        if not self.cloud_available:
            return Decision.drop(task, TaskState.DROPPED_TIME, f"{why}; cloud unavailable at its trigger")
        return Decision.cloud(task, why)

    # -- JIT
    def poll(self, now_ms: float) -> list[Decision]:
        out = []
        while (h := self.tentative.head()) is not None and h.key - now_ms <= JIT_EARLY_MS:
            self.tentative.pop_head()
            if h.kind == "cost":
                out.append(Decision.drop(h.task, TaskState.DROPPED_COST,
                                         f"cloud utility {self.w[h.task.model].cloud_utility:g} <= 0 and not stolen by "
                                         "the edge before its edge trigger"))
            elif h.key - now_ms < -JIT_LATE_MS:
                self.counters["jit_dropped_past_trigger"] += 1
                out.append(Decision.drop(h.task, TaskState.DROPPED_TIME,
                                         f"missed its cloud trigger by {now_ms - h.key:.0f} ms"))
            else:
                self.counters["jit_released"] += 1
                self.counters["jit_released_after_trigger"] += int(now_ms > h.key)
                out.append(self._release(h.task, now_ms, "just-in-time release from the tentative cloud queue"))
        return self._settle(out, now_ms)

    def next_poll_ms(self) -> float | None:
        h = self.tentative.head()
        return None if h is None else h.key - JIT_EARLY_MS

    # -- work stealing
    def steal_rank(self, task: AnalyticsTask) -> float:
        """Work-stealing rank (Application.getUtilityDiff): (cloud cost - edge cost) * 1000 / edge_ms, plus 1000 for
        a model with negative cloud utility. Higher is stolen first."""
        p = self.w[task.model]
        rank = (p.cloud_cost - p.edge_cost) * 1000.0 / max(p.edge_ms, 1.0)
        return rank + (1000.0 if p.cloud_utility < 0 else 0.0)

    def _steal(self, now_ms: float, slack_ms: float | None) -> AnalyticsTask | None:
        """The best-ranked held task the edge can run now: it fits its own deadline and, when ``slack_ms`` is
        given (queue busy), its edge time is below the slack and no queued task would miss behind it."""
        c = self.counters
        c["steal_attempts_idle" if slack_ms is None else "steal_attempts_busy"] += 1
        for h in sorted(self.tentative.entries(), key=lambda h: (-self.steal_rank(h.task), h.key, h.seq)):
            e = self.queue.edge_ms(h.task)
            if now_ms + e > h.task.deadline_ms:
                c["steal_rejected_own_deadline"] += 1
                continue
            if slack_ms is not None and e >= slack_ms:
                c["steal_rejected_over_slack"] += 1
                continue
            if slack_ms is not None and self.queue.first_violation(now_ms + e) is not None:
                c["steal_rejected_queue_would_miss"] += 1
                continue
            self.tentative.remove(h)
            h.task.notes["stolen"] = True
            c["steals"] += 1
            return h.task
        return None

    def _pop_edge(self, now_ms: float) -> tuple[AnalyticsTask | None, list[Decision]]:
        drops: list[Decision] = []
        while True:
            if not self.queue:
                stolen = self._steal(now_ms, None) if self.steal_when_idle and self.tentative else None
                return stolen, self._settle(drops, now_ms)
            head = self.queue.tasks[0]
            slack = head.deadline_ms - self.queue.edge_ms(head) - EDGE_TRIGGER_BUFFER_MS - now_ms
            if self.tentative and slack <= self.steal_slack_ms:
                self.counters["steal_skipped_slack_below_min_edge"] += 1
            if self.tentative and slack > self.steal_slack_ms:
                stolen = self._steal(now_ms, slack)
                if stolen is not None:
                    return stolen, self._settle(drops, now_ms)
            t, d = self.queue.pop_head(now_ms)
            if t is not None:
                return t, self._settle(drops, now_ms)
            drops.append(d)

    def held_tasks(self) -> list[AnalyticsTask]:
        return list(self.queue) + self.tentative.tasks()


# --------------------------------------------------------------------------------------------- DEMS-A
class DemsA(Dems):
    """DEMS-A (algorithm 91): DEMS adapting to cloud latency.

    * Estimate: per model, a sliding window of the last 10 observed cloud latencies (every cloud completion,
      late ones included); when the window is full and its mean differs from the current estimate by more than
      10 ms, the mean becomes the estimate (:class:`CloudLatencyEstimator`). New decisions (time checks, cloud
      triggers, eviction scores) use the estimate; a held task keeps the estimate it was held with.
    * Cool-down: the first time a rejected/evicted task of a model fails the cloud-time check, that model's
      cool-down starts (the task is dropped for time). During the next 10 s its tasks that fail the check are
      dropped for time. The first one that fails the check after 10 s ends the cool-down and *probes*: it is
      re-checked with the profile's cloud time and, if that fits, held for the cloud with it. When a probe
      completes on time, the latency window is refilled with its latency (so the estimate snaps to it). Any
      on-time cloud completion of the model during a cool-down ends the cool-down.
    """

    name = "DEMS-A"
    cooldown_ms: ClassVar[float] = 10_000.0

    def __init__(self, workload: Workload, **options) -> None:
        super().__init__(workload, **options)
        self.cooling_since: dict[str, float | None] = {m: None for m in workload.models}

    def _default_estimator(self, workload: Workload) -> LatencyEstimator | None:
        return WindowMeanEstimator(workload)

    def _cloud_too_slow(self, task: AnalyticsTask, now_ms: float, est_ms: float, why: str) -> list[Decision]:
        m, left = task.model, task.deadline_ms - now_ms
        since = self.cooling_since[m]
        if since is None:
            self.cooling_since[m] = now_ms
            return [Decision.drop(task, TaskState.DROPPED_TIME, f"{why}; cloud estimate {est_ms:.0f} ms exceeds the "
                                  f"{left:.0f} ms left; {m} cloud cool-down starts")]
        if now_ms - since <= self.cooldown_ms:
            return [Decision.drop(task, TaskState.DROPPED_TIME, f"{why}; cloud estimate {est_ms:.0f} ms exceeds the "
                                  f"{left:.0f} ms left; {m} in cloud cool-down")]
        self.cooling_since[m] = None
        probe = self.w[m].cloud_ms
        if now_ms + probe > task.deadline_ms:
            return [Decision.drop(task, TaskState.DROPPED_TIME, f"{why}; cool-down over but even the profile cloud "
                                  f"time {probe:.0f} ms exceeds the {left:.0f} ms left")]
        task.notes["probe"] = True
        return self._hold_for_cloud(task, now_ms, probe, f"{why}; cool-down over, probing with the profile cloud time")

    def on_cloud_done(self, task: AnalyticsTask, now_ms: float, latency_ms: float) -> list[Decision]:
        m = task.model
        if task_on_time(task, now_ms):
            if self.cooling_since[m] is not None:
                self.cooling_since[m] = None
            elif task.notes.get("probe"):
                self.latency.refill(m, latency_ms)
        return super().on_cloud_done(task, now_ms, latency_ms)  # observes completions only, as the reference


# --------------------------------------------------------------------------------------------- GEMS
class Gems(Dems):
    """GEMS (algorithm 35): DEMS plus a QoE *gatekeeper* (GateKeeper.java, version 0).

    Time is cut into tumbling windows of 20 s (the first starts at the first terminal event). Within a window,
    per model, the gatekeeper counts terminal tasks and those done on time. After every terminal event it
    checks each model: if its on-time fraction so far in this window is below 0.9, every task of that model
    waiting in the edge queue whose cloud utility is positive and whose cloud time still fits is removed from
    the edge queue and sent to the cloud at once. Counts restart with each window.
    """

    name = "GEMS"
    window_ms: ClassVar[float] = 20_000.0
    required_fraction: ClassVar[float] = 0.9

    def __init__(self, workload: Workload, **options) -> None:
        super().__init__(workload, **options)
        self.window_start_ms: float | None = None
        self.done_on_time: Counter[str] = Counter()
        self.terminal: Counter[str] = Counter()

    def _roll(self, now_ms: float) -> None:
        if self.window_start_ms is None:
            self.window_start_ms = now_ms
        elif now_ms >= self.window_start_ms + self.window_ms:
            self.window_start_ms += self.window_ms * ((now_ms - self.window_start_ms) // self.window_ms)
            self.done_on_time.clear()
            self.terminal.clear()

    def _observe_terminal(self, task: AnalyticsTask, now_ms: float, on_time: bool) -> None:
        self._roll(now_ms)
        self.terminal[task.model] += 1
        self.done_on_time[task.model] += int(on_time)

    def on_time_fraction(self, model: str) -> float | None:
        """On-time fraction of ``model`` in the current window (None before its first terminal task)."""
        n = self.terminal[model]
        return self.done_on_time[model] / n if n else None

    def _settle(self, decisions: list[Decision], now_ms: float) -> list[Decision]:
        decisions = super()._settle(decisions, now_ms)
        if not self.cloud_available or self.window_start_ms is None:
            return decisions
        self._roll(now_ms)
        low = {m: f for m in self.terminal if (f := self.on_time_fraction(m)) is not None and f < self.required_fraction}
        if not low:
            return decisions
        for t in list(self.queue):
            p = self.w[t.model]
            if t.model in low and p.cloud_utility > 0 and now_ms + self.cloud_estimate_ms(t.model) <= t.deadline_ms:
                self.queue.remove(t)
                self.counters["gatekeeper_migrations"] += 1
                decisions.append(Decision.cloud(t, f"gatekeeper: {t.model} on-time fraction {low[t.model]:.2f} < "
                                                   f"{self.required_fraction} in this window"))
        return decisions
