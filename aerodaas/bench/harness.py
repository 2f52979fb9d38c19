"""The deterministic policy harness: analytics-scheduler policies driven on simulated time, without Ray.

It drives a policy exactly the way :class:`aerodaas.schedulers.dispatch.dispatcher.AnalyticsDispatcher` does: ``submit``
on arrival, ``next_edge_task`` whenever the edge is free (after every event), ``poll`` at ``next_poll_ms``,
``cloud_admit`` before a cloud execution (bisected into an admit-by time with :func:`admit_by_time`, a dozen calls per
task, as the dispatcher does), ``on_edge_done`` / ``on_cloud_done(task, now, latency_ms)`` on completion, and drops
``held_tasks()`` at the end. The emulated edge runs one task at a time; the cloud runs any number at once.

Timing is the runtime benchmark's, drawn from the same seeded streams (``seeded_rng(seed, "edge"|"cloud", edge_id,
task_id)``, task ids counted from 1 per edge in arrival order, as the dispatcher numbers them): an edge execution takes
``edge_ms`` x the edge jitter factor, a cloud round trip ``cloud_ms`` x the cloud jitter factor + the
:class:`~aerodaas.schedulers.dispatch.emulation.NetworkModel`'s extra latency at the send time (+ ``cloud_extra_ms``, a
constant or ``(task, send_ms) -> ms``, for hand-built scenarios). With no jitter and no network model the timing is
exact. So the harness reproduces what the Ray benchmark measures minus its wall-clock emulation error (``aerodaas bench
schedulers --harness``, :mod:`aerodaas.bench.sweep`).

:func:`make_trace` is the single-edge arrival process of the policy tests; fleets use
:func:`aerodaas.bench.workload.make_trace` (the runtime benchmark's) through :func:`run_fleet`.
"""
from __future__ import annotations

import heapq
import itertools
import random
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from typing import Callable, Sequence

from aerodaas.schedulers.dispatch.emulation import Jitter, NetworkModel, seeded_rng
from aerodaas.schedulers.analytics_base import (AnalyticsScheduler, AnalyticsTask, CloudCounters, Decision, TaskState,
                                                Workload, admit_by_time, filter_options, make_analytics_scheduler,
                                                task_utility)

__all__ = ["Harness", "Result", "make_trace", "run_policy", "fleet_tasks", "run_fleet"]


def make_trace(workload: Workload, *, drones: int = 2, fps: float = 1.0, duration_s: float = 60.0, seed: int = 0,
               jitter_ms: float = 20.0) -> list[AnalyticsTask]:
    """Seeded single-edge arrival trace: ``drones`` drones each send a frame every ``1000 / fps`` ms from a random
    phase plus uniform [0, ``jitter_ms``] ms, and each frame creates one task per active model in shuffled order
    (Ocularone ``TaskCreation.java``). Tasks are numbered in arrival order."""
    rng = random.Random(seed)
    period = 1000.0 / fps
    rows = []
    for d in range(drones):
        phase = rng.uniform(0.0, period)
        for k in itertools.count():
            t = phase + k * period + rng.uniform(0.0, jitter_ms)
            if t >= duration_s * 1000.0:
                break
            models = list(workload.models)
            rng.shuffle(models)
            rows += [(t, d, i, m) for i, m in enumerate(models)]
    rows.sort()
    return [AnalyticsTask(n, f"drone{d}", m, t, t + workload[m].deadline_ms) for n, (t, d, _, m) in enumerate(rows)]


@dataclass
class Result:
    """Outcome of one run: the tasks (terminal), total utility and bookkeeping for the invariants."""

    tasks: list[AnalyticsTask]
    utility: float
    states: Counter
    tiers: Counter
    #: (task, start_ms) of every edge start, in order
    edge_starts: list = field(default_factory=list)
    #: (task, send_ms) of every cloud execution, in order
    cloud_sends: list = field(default_factory=list)
    #: tasks that reached a terminal state more than once (must stay empty)
    double_terminal: list = field(default_factory=list)
    #: tasks given to the edge or the cloud while not pending (must stay empty)
    bad_dispatch: list = field(default_factory=list)
    #: the decision log: (now_ms, kind, task_id, state or None, reason)
    log: list = field(default_factory=list)
    #: the policy's behaviour counters plus the harness's cloud counters (:class:`CloudCounters`)
    counters: dict = field(default_factory=dict)

    def completion(self) -> float:
        """Fraction of tasks done on time."""
        return self.states[TaskState.DONE_ON_TIME] / max(1, len(self.tasks))

    def cost(self, workload: Workload, tier: str) -> float:
        """Summed ``tier`` cost ("edge"/"cloud") charged in this run."""
        return sum(getattr(workload[t.model], f"{tier}_cost") for t in self.tasks
                   if t.tier == tier and t.state in (TaskState.DONE_ON_TIME, TaskState.DONE_LATE, TaskState.FAILED))


class Harness:
    """Run ``policy`` over a trace on simulated time (see the module docstring). ``cloud_down``: (start_ms, end_ms)
    intervals during which the cloud is reported unavailable. ``admit_probes`` False calls ``cloud_admit`` once
    per cloud task instead of bisecting as the dispatcher does (a pure policy gives the same result either way).
    ``edge_jitter`` / ``cloud_jitter`` / ``network`` / ``seed`` / ``edge_id``: the runtime's timing model; ``seed``
    an int (published runs) or 32 secret bytes (:func:`aerodaas.bench.isolation.secret_seed`, the non-anticipation
    test: a draw can then be neither recomputed nor its seed searched for)."""

    def __init__(self, policy: AnalyticsScheduler, *, cloud_extra_ms: float | Callable = 0.0,
                 cloud_down: Sequence[tuple[float, float]] = (), admit_probes: bool = True,
                 edge_jitter: Jitter | None = None, cloud_jitter: Jitter | None = None,
                 network: NetworkModel | None = None, seed: int | bytes = 0, edge_id: str = "edge00") -> None:
        self.p = policy
        self.admit_probes = admit_probes
        self.w = policy.w
        self.extra = cloud_extra_ms if callable(cloud_extra_ms) else (lambda task, t, c=float(cloud_extra_ms): c)
        self.cloud_down = list(cloud_down)
        self.edge_jitter, self.cloud_jitter, self.network = edge_jitter, cloud_jitter, network
        # an int (a published, reproducible run) or bytes (a secret from aerodaas.bench.isolation.secret_seed)
        self.seed, self.edge_id = (seed if isinstance(seed, bytes) else int(seed)), edge_id
        self.cloud = CloudCounters()
        self._events: list = []
        self._seq = itertools.count()
        self._edge_task: AnalyticsTask | None = None
        self._poll_at: float | None = None
        self._terminal: Counter = Counter()
        self.now = 0.0

    # -- timing model
    def edge_hold_ms(self, task: AnalyticsTask) -> float:
        """How long the edge runs ``task`` (ms): the profile x the edge jitter factor."""
        e = self.w[task.model].edge_ms
        if self.edge_jitter is None:
            return e
        return e * self.edge_jitter.factor(seeded_rng(self.seed, "edge", self.edge_id, task.task_id))

    def cloud_round_trip_ms(self, task: AnalyticsTask, send_ms: float) -> float:
        """Cloud round trip (ms) of ``task`` sent at ``send_ms``: drawn as
        :meth:`aerodaas.schedulers.dispatch.cloud_pool.CloudPool.send` does (network first, then the jitter factor, from
        one seeded stream), plus ``cloud_extra_ms``."""
        c = self.w[task.model].cloud_ms
        if self.cloud_jitter is not None or self.network is not None:
            rng = seeded_rng(self.seed, "cloud", self.edge_id, task.task_id)
            net = self.network.sample(send_ms, rng) if self.network is not None else 0.0
            c = c * (self.cloud_jitter.factor(rng) if self.cloud_jitter is not None else 1.0) + net
        return c + self.extra(task, send_ms)

    # -- event loop
    def _push(self, t: float, kind: str, obj) -> None:
        heapq.heappush(self._events, (t, next(self._seq), kind, obj))

    def _terminate(self, task: AnalyticsTask, state: TaskState, reason: str) -> None:
        self._terminal[task.task_id] += 1
        if self._terminal[task.task_id] > 1:
            self.res.double_terminal.append(task)
        task.state, task.reason = state, reason
        self.res.log.append((self.now, "terminal", task.task_id, state, reason))

    def _apply(self, decisions: list[Decision]) -> None:
        for d in decisions:
            t = d.task
            self.res.log.append((self.now, d.kind, t.task_id, d.state, d.reason))
            if t.state is not TaskState.PENDING or t.tier is not None:
                self.res.bad_dispatch.append(t)
                continue
            if d.kind == "drop":
                self._terminate(t, d.state, d.reason)
            elif not self._admits(t):
                self._terminate(t, TaskState.DROPPED_TIME, "cloud re-check failed")
                self._apply(self.p.on_cloud_done(t, self.now, 0.0))  # the dispatcher's contract
            else:
                t.tier, t.start_ms = "cloud", self.now
                self.res.cloud_sends.append((t, self.now))
                self.cloud.on_send(self.now)
                self._push(self.now + self.cloud_round_trip_ms(t, self.now), "cloud_done", t)

    def _admits(self, t: AnalyticsTask) -> bool:
        if self.admit_probes:
            return admit_by_time(lambda at: self.p.cloud_admit(t, at), self.now, t.deadline_ms) is not None
        return self.p.cloud_admit(t, self.now)

    def _kick(self) -> None:
        if self._edge_task is None:
            task, decisions = self.p.next_edge_task(self.now)
            self._apply(decisions)
            if task is not None:
                if task.state is not TaskState.PENDING or task.tier is not None:
                    self.res.bad_dispatch.append(task)
                else:
                    task.tier, task.start_ms = "edge", self.now
                    self._edge_task = task
                    self.res.edge_starts.append((task, self.now))
                    self._push(self.now + self.edge_hold_ms(task), "edge_done", task)
        nxt = self.p.next_poll_ms()
        if nxt is not None:
            at = max(nxt, self.now)
            if self._poll_at is None or at != self._poll_at:
                self._poll_at = at
                self._push(at, "poll", at)

    def run(self, trace: list[AnalyticsTask], *, max_events: int = 2_000_000,
            until_ms: float | None = None) -> Result:
        """Run the trace to the end (``until_ms`` None): every task ends in exactly one terminal state. Raises
        RuntimeError after ``max_events`` events (a policy polling in a loop).

        ``until_ms``: stop before the first event at or after this simulated time (ms). The result's log and edge
        starts are then exactly the full run's before ``until_ms`` (no event schedules another before its own time:
        edge holds, cloud round trips and network delays are >= 0, a poll is never in the past; a negative
        ``cloud_extra_ms`` would break this) and nothing after: no end-of-run terminations, the tasks left as they
        stand, and ``utility``, ``states``, ``tiers`` and ``counters`` left empty."""
        self.res = Result(trace, 0.0, Counter(), Counter())
        for t in trace:
            self._push(t.arrival_ms, "arrive", t)
        for t0, t1 in self.cloud_down:
            self._push(t0, "cloud", False)
            self._push(t1, "cloud", True)
        n = 0
        while self._events:
            if until_ms is not None and self._events[0][0] >= until_ms:
                return self.res
            n += 1
            if n > max_events:
                raise RuntimeError(f"{self.p.name}: more than {max_events} events (a poll loop?)")
            self.now, _, kind, obj = heapq.heappop(self._events)
            if kind == "arrive":
                self._apply(self.p.submit(obj, self.now))
            elif kind == "edge_done":
                obj.end_ms = self.now
                self._edge_task = None
                self._terminate(obj, TaskState.DONE_ON_TIME if self.now <= obj.deadline_ms else TaskState.DONE_LATE,
                                "edge done")
                self._apply(self.p.on_edge_done(obj, self.now, self.now - obj.start_ms))
            elif kind == "cloud_done":
                obj.end_ms = self.now
                self._terminate(obj, TaskState.DONE_ON_TIME if self.now <= obj.deadline_ms else TaskState.DONE_LATE,
                                "cloud done")
                self.cloud.on_end(obj, self.now)
                self._apply(self.p.on_cloud_done(obj, self.now, self.now - obj.start_ms))
            elif kind == "poll":
                if obj != self._poll_at:
                    continue  # superseded
                self._poll_at = None
                self._apply(self.p.poll(self.now))
            elif kind == "cloud":
                self._apply(self.p.on_cloud_availability(obj, self.now))
            self._kick()
        for t in self.p.held_tasks():
            self._terminate(t, TaskState.DROPPED_TIME, "run ended")
        self.res.utility = sum(task_utility(t, self.w[t.model]) for t in trace if t.state is not TaskState.PENDING)
        self.res.states = Counter(t.state for t in trace)
        self.res.tiers = Counter(t.tier for t in trace)
        self.res.counters = {**dict(self.p.counters), **self.cloud.summary()}
        return self.res


def _fresh(trace: Sequence[AnalyticsTask]) -> list[AnalyticsTask]:
    return [AnalyticsTask(t.task_id, t.drone, t.model, t.arrival_ms, t.deadline_ms) for t in trace]


def run_policy(name: str, workload: Workload, trace: Sequence[AnalyticsTask], *, options: dict | None = None,
               factory: Callable[[Workload], AnalyticsScheduler] | None = None, **harness_kw) -> Result:
    """Fresh copies of the trace's tasks through a fresh ``name`` scheduler (``options``: constructor options,
    those the policy does not accept are ignored, see :func:`filter_options`; ``factory(workload)``: build the
    policy instead, e.g. a variant that is not registered)."""
    pol = factory(workload) if factory else make_analytics_scheduler(name, workload, **filter_options(name, options or {}))
    return Harness(pol, **harness_kw).run(_fresh(trace))


def fleet_tasks(rows: Sequence[tuple[float, str, str, str]], workload: Workload) -> dict[str, list[AnalyticsTask]]:
    """Split the runtime benchmark's trace rows ``(arrival_ms, edge_id, drone, model)`` into per-edge task lists,
    numbered from 1 per edge in row order (as each edge's dispatcher numbers its submissions)."""
    out: dict[str, list[AnalyticsTask]] = defaultdict(list)
    for t, edge, drone, model in rows:
        lst = out[edge]
        lst.append(AnalyticsTask(len(lst) + 1, drone, model, t, t + workload[model].deadline_ms))
    return dict(out)


def run_fleet(name: str, workload: Workload, per_edge: dict[str, list[AnalyticsTask]], *, seed: int,
              edge_jitter: Jitter | None, cloud_jitter: Jitter | None, network_specs: Sequence[str] = (),
              options: dict | None = None, factory: Callable[[Workload], AnalyticsScheduler] | None = None) -> dict:
    """Every edge of a fleet through its own fresh ``name`` policy (as the runtime: one policy per edge, one
    unbounded cloud). Returns the summed figures: ``tasks``, ``utility``, ``on_time``, ``cloud_cost``,
    ``edge_cost``, ``states`` and ``counters`` (sums; ``cloud_peak_concurrency`` is the largest edge's)."""
    tot = {"tasks": 0, "utility": 0.0, "on_time": 0, "cloud_cost": 0.0, "edge_cost": 0.0}
    states, counters = Counter(), Counter()
    peak = 0
    for edge, trace in per_edge.items():
        res = run_policy(name, workload, trace, options=options, factory=factory, edge_jitter=edge_jitter,
                         cloud_jitter=cloud_jitter,
                         network=NetworkModel.parse(list(network_specs), seed), seed=seed, edge_id=edge)
        tot["tasks"] += len(res.tasks)
        tot["utility"] += res.utility
        tot["on_time"] += res.states[TaskState.DONE_ON_TIME]
        tot["cloud_cost"] += res.cost(workload, "cloud")
        tot["edge_cost"] += res.cost(workload, "edge")
        states.update({s.value: n for s, n in res.states.items()})
        peak = max(peak, res.counters.get("cloud_peak_concurrency", 0))
        counters.update({k: v for k, v in res.counters.items() if k != "cloud_peak_concurrency"})
    counters["cloud_peak_concurrency_per_edge"] = peak
    return {**tot, "states": dict(states), "counters": dict(counters)}
