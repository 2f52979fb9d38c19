"""A deterministic exact-timing driver for analytics-scheduler policies — a *test harness only* (the real
experiments run the policies in the Ray dispatcher on wall-clock time).

It drives a policy the way the dispatcher does: ``submit`` on arrival, ``next_edge_task`` whenever the edge is
free (after every event), ``poll`` at ``next_poll_ms``, ``cloud_admit`` before a cloud execution (bisected into
an admit-by time with the dispatcher's own ``analytics_base.admit_by_time``, a dozen calls per task),
``on_edge_done`` / ``on_cloud_done(task, now, latency_ms)`` on completion, and drops ``held_tasks()`` at the end.
The emulated edge runs one task at a time for exactly the profile's ``edge_ms``; the cloud runs any number at
once for exactly ``cloud_ms`` + a configurable extra latency.

Arrival process (:func:`make_trace`): ``drones`` drones each send one 1-frame batch every ``1000 / fps`` ms
(random phase per drone, uniform jitter), and each batch creates one task per active model in shuffled order
(Ocularone ``TaskCreation.java``). The Ocularone experiments use 1-frame batches and, in the README's example,
2 drones per edge; see docs/analytics-schedulers.md.
"""
from __future__ import annotations

import heapq
import itertools
import random
from collections import Counter
from dataclasses import dataclass, field
from typing import Callable

from aerodaas.schedulers.analytics_base import (AnalyticsScheduler, AnalyticsTask, Decision, TaskState, Workload,
                                                admit_by_time, task_utility)


def make_trace(workload: Workload, *, drones: int = 2, fps: float = 1.0, duration_s: float = 60.0, seed: int = 0,
               jitter_ms: float = 20.0) -> list[AnalyticsTask]:
    """Seeded arrival trace: one task per active model per frame, frames per drone every 1000/fps ms."""
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

    def completion(self) -> float:
        return self.states[TaskState.DONE_ON_TIME] / max(1, len(self.tasks))


class Harness:
    """Run ``policy`` over a trace with exact timing. ``cloud_extra_ms`` is a constant or a function
    ``(task, send_ms) -> extra ms`` added to the profile's cloud time; ``cloud_down`` is a list of
    (start_ms, end_ms) intervals during which the cloud is reported unavailable. ``admit_probes`` False calls
    ``cloud_admit`` once per cloud task instead of bisecting as the dispatcher does (a pure policy gives the same
    result either way)."""

    def __init__(self, policy: AnalyticsScheduler, *, cloud_extra_ms: float | Callable = 0.0,
                 cloud_down: list[tuple[float, float]] = (), admit_probes: bool = True) -> None:
        self.p = policy
        self.admit_probes = admit_probes
        self.w = policy.w
        self.extra = cloud_extra_ms if callable(cloud_extra_ms) else (lambda task, t, c=float(cloud_extra_ms): c)
        self.cloud_down = list(cloud_down)
        self._events: list = []
        self._seq = itertools.count()
        self._edge_task: AnalyticsTask | None = None
        self._poll_at: float | None = None
        self._terminal: Counter = Counter()
        self.now = 0.0

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
                self._push(self.now + self.w[t.model].cloud_ms + self.extra(t, self.now), "cloud_done", t)

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
                    self._push(self.now + self.w[task.model].edge_ms, "edge_done", task)
        nxt = self.p.next_poll_ms()
        if nxt is not None:
            at = max(nxt, self.now)
            if self._poll_at is None or at != self._poll_at:
                self._poll_at = at
                self._push(at, "poll", at)

    def run(self, trace: list[AnalyticsTask], *, max_events: int = 2_000_000) -> Result:
        self.res = Result(trace, 0.0, Counter(), Counter())
        for t in trace:
            self._push(t.arrival_ms, "arrive", t)
        for t0, t1 in self.cloud_down:
            self._push(t0, "cloud", False)
            self._push(t1, "cloud", True)
        n = 0
        while self._events:
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
        return self.res


def run_policy(name: str, workload: Workload, trace: list[AnalyticsTask], **harness_kw) -> Result:
    """Fresh copies of the trace's tasks through a fresh ``name`` scheduler."""
    from aerodaas.schedulers.analytics_base import make_analytics_scheduler

    tasks = [AnalyticsTask(t.task_id, t.drone, t.model, t.arrival_ms, t.deadline_ms) for t in trace]
    return Harness(make_analytics_scheduler(name, workload), **harness_kw).run(tasks)


if __name__ == "__main__":  # the utility table of docs/analytics-schedulers.md
    import argparse
    import os

    from aerodaas.schedulers.analytics_base import analytics_scheduler_names

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--duration", type=float, default=120.0)
    ap.add_argument("--drones", type=int, default=2)
    ap.add_argument("--extra", type=float, default=0.0, help="constant extra cloud latency, ms")
    ap.add_argument("--step", type=float, default=0.0, help="extra cloud latency (ms) during the last 20 s of every minute")
    ap.add_argument("--jitter", type=float, default=0.0, help="extra cloud latency drawn uniformly from [0, JITTER] ms")
    a = ap.parse_args()
    path = os.path.join(os.environ.get("AERODAAS_DATA_DIR", "../shared/data"), "workloads", "ocularone_lambda.json")
    names = analytics_scheduler_names()
    print(f"drones/edge={a.drones} fps=1 duration={a.duration:.0f}s seeds={a.seeds} extra={a.extra:.0f} ms "
          f"step={a.step:.0f} ms jitter={a.jitter:.0f} ms; mean utility per run (on-time completion)")
    print(f"{'scheduler':10}" + "".join(f"{load:>20}" for load in ("LIGHT", "MEDIUM", "HEAVY")))
    rows = {}
    for load in ("LIGHT", "MEDIUM", "HEAVY"):
        w = Workload.from_file(path, load)
        for name in names:
            us, cs = [], []
            for seed in range(a.seeds):
                rng = random.Random(seed)

                def extra(task, t, rng=rng):
                    return a.extra + (a.step if t % 60_000 >= 40_000 else 0.0) + rng.uniform(0.0, a.jitter)

                r = run_policy(name, w, make_trace(w, drones=a.drones, duration_s=a.duration, seed=seed),
                               cloud_extra_ms=extra)
                us.append(r.utility)
                cs.append(r.completion())
            rows.setdefault(name, []).append((sum(us) / len(us), sum(cs) / len(cs)))
    for name, cells in rows.items():
        print(f"{name:10}" + "".join(f"{u:>12.0f} ({100 * c:3.0f}%)" for u, c in cells))
