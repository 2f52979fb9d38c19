"""The analytics dispatcher: :class:`AnalyticsDispatcher` carries out one analytics scheduler's decisions for one
edge device, on a real Ray cluster, with wall-clock time.

An analytics scheduler (:class:`aerodaas.schedulers.analytics_base.AnalyticsScheduler`) is a pure policy. The
dispatcher -- one per edge device -- owns one policy instance, a monotonic millisecond clock
(:class:`~aerodaas.schedulers.dispatch.clock.Clock`), the edge executor loop (one task at a time; asks
``next_edge_task`` whenever the edge is free; :mod:`~aerodaas.schedulers.dispatch.edge_executors`), a timer that
calls ``poll`` at ``next_poll_ms``, and cloud submission through a
:class:`~aerodaas.schedulers.dispatch.cloud_pool.CloudPool`. It records every task's terminal state, tier, times
and reason, computes utility with ``task_utility``, and times every policy call (decision latency in
microseconds). :meth:`AnalyticsDispatcher.submit` is thread-safe, cheap and non-blocking, so an edge host's frame
path can call it directly.

Threads and clocks
------------------
Everything of one dispatcher runs on one asyncio event loop: the edge loop is a coroutine, the poll timer a
``loop.call_at`` handle, cloud replies arrive as awaited Ray ObjectRefs. Policy calls therefore happen on one
thread, under one lock (the contract of ``analytics_base``). Inside a Ray async actor (e.g. the benchmark's
:class:`aerodaas.bench.edge_host.EdgeHost`) the actor's own loop is used; elsewhere
:meth:`AnalyticsDispatcher.start_background` starts a private loop thread.
:meth:`~AnalyticsDispatcher.submit` stamps the arrival time on the caller's thread (unless ``arrival_ms`` is
given) and hands the task to the loop with ``call_soon_threadsafe``.

Times given to policies are ms on the dispatcher's :class:`Clock` (``time.monotonic`` since the run's ``t0``).
Times that cross processes (cloud hold targets, the cloud re-check) are epoch seconds (``time.time``): exact on one
machine, NTP-accurate across machines.

The cloud re-check (``cloud_admit``)
------------------------------------
The policy lives on the edge, the check must happen on the cloud right before execution. When a task is sent, the
dispatcher turns ``policy.cloud_admit(task, t)`` into an *admit-by* time: the latest ``t`` (1 ms resolution,
bisection between now and the deadline) at which the policy still admits the task, on the policy's current
estimate (``cloud_estimate_ms``). That assumes ``cloud_admit`` is monotone in ``t`` (true for every "enough time
left" test); a policy that admits at any time (the CLOUD baseline) gets no limit. The admit-by epoch travels with
the task; the cloud executor compares it with its clock when the request reaches it and, in real mode, again when a
detector thread picks the task up (queueing beyond the admit-by time). Emulated network latency (``NetworkModel``)
comes *after* the check: the reference makes its check right before the HTTP call to its Lambda function
(``TaskExecutorLambda``), so the network's delay is part of the round trip the check has already admitted, and the
task comes back late rather than being refused. A refused task ends as DROPPED_TIME with reason ``cloud re-check``;
it never ran, so adaptive policies do not take its reply time as a latency sample.

Reference for the policies, the workload and the utility model: S. Raj, R. Mittal, H. Gupta, Y. Simmhan,
"Adaptive heuristics for scheduling DNN inferencing on edge and cloud for personalized UAV fleets", FGCS 2025
(arXiv 2412.20860).
"""
from __future__ import annotations

import asyncio
import itertools
import logging
import re
import threading
import time
from collections import Counter, defaultdict
from typing import Any, Callable, Iterable

from aerodaas.schedulers.analytics_base import (
    AnalyticsScheduler, AnalyticsTask, CloudCounters, Decision, TaskState, Workload, admit_by_time, task_utility,
)

from aerodaas.schedulers.dispatch.clock import Clock
from aerodaas.schedulers.dispatch.cloud_pool import CloudPool
from aerodaas.schedulers.dispatch.edge_executors import EdgeExecutor
from aerodaas.schedulers.dispatch.stats import Samples

__all__ = ["AnalyticsDispatcher", "DROP_STATES"]

log = logging.getLogger(__name__)


DROP_STATES = (TaskState.DROPPED_TIME, TaskState.DROPPED_COST, TaskState.EXPIRED_EDGE)
_DONE_STATES = (TaskState.DONE_ON_TIME, TaskState.DONE_LATE)


_FAILED = object()  # sentinel: a policy call raised


def _reason_key(reason: str) -> str:
    """A reason with its numbers replaced by '#', so drops can be counted by kind."""
    return re.sub(r"-?\d+(\.\d+)?", "#", reason)


class _LoopThread:
    """An asyncio event loop running in a daemon thread."""

    def __init__(self, name: str) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, name=name, daemon=True)
        self.thread.start()

    def run(self, coro, timeout: float | None = None):
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    def stop(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)


class AnalyticsDispatcher:
    """Carries out one analytics scheduler's decisions for one edge device, on the wall clock.

    ``policy``: an :class:`AnalyticsScheduler` (one instance per edge device; the dispatcher owns it).
    ``edge``: the :class:`EdgeExecutor` (emulated or ONNX). ``cloud``: a :class:`CloudPool` (may be shared with
    other dispatchers of the same loop) or None for an edge-only device. ``clock``: the :class:`Clock` (share one to
    give several dispatchers one time origin). ``on_result(task)`` is called (on the loop) for every task that
    reaches its terminal state, with its ``payload`` still attached (released right after). ``keep_tasks``: keep every task object for :meth:`tasks` (set False for long-running
    use; the counters stay exact).

    Lifecycle: ``await start()`` on the loop that will run it (or :meth:`start_background` from synchronous code),
    :meth:`submit` from any thread, then ``await finish()`` (or :meth:`finish_background`) for the report.

    Accounting: every submitted task is registered before :meth:`submit` returns and ends in exactly one terminal
    state. A decision about a task that is already terminal (a policy bug) is ignored and counted in
    ``accounting.policy_errors``, as are exceptions raised by the policy (the task involved ends FAILED).
    """

    def __init__(self, policy: AnalyticsScheduler, edge: EdgeExecutor, cloud: CloudPool | None = None, *,
                 edge_id: str = "edge0", clock: Clock | None = None,
                 on_result: Callable[[AnalyticsTask], None] | None = None, keep_tasks: bool = True,
                 sample_seed: int = 0) -> None:
        if not isinstance(policy, AnalyticsScheduler):
            raise TypeError(f"policy must be an AnalyticsScheduler, got {type(policy).__name__}")
        self.policy = policy
        self.workload: Workload = policy.w
        self.edge = edge
        self.cloud = cloud
        self.edge_id = edge_id
        self.clock = clock or Clock()
        self.on_result = on_result
        self.keep_tasks = keep_tasks
        self._lock = threading.RLock()
        self._ids = itertools.count(1)
        self._tasks: dict[int, AnalyticsTask] = {}
        self._pending: set[int] = set()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: _LoopThread | None = None
        self._wake: asyncio.Event | None = None
        self._edge_task: asyncio.Task | None = None
        self._poll_handle: asyncio.TimerHandle | None = None
        self._poll_at: float | None = None
        self._stopping = False
        self._owns_cloud = False
        self._closing = False
        self._closed = False
        self._idle_event: asyncio.Event | None = None
        self.started_ms: float | None = None
        self.finished_ms: float | None = None
        # statistics
        self.submitted = 0
        self.states: Counter = Counter()
        self.tiers: Counter = Counter()
        self.reasons: Counter = Counter()
        self.utility = 0.0
        self.utility_by_model: Counter = Counter()
        self.count_by_model: Counter = Counter()
        self.ontime_by_model: Counter = Counter()
        self.cloud_cost = 0.0
        self.edge_cost = 0.0
        self.edge_busy_ms = 0.0
        self.policy_errors: list[str] = []
        self.decision_us = Samples(seed=sample_seed)
        self.decision_by_call: dict[str, Samples] = defaultdict(lambda: Samples(cap=50_000, seed=sample_seed))
        #: policy call name -> CPU ns spent in it (thread time; its wall time also counts waiting for a core)
        self.policy_cpu_ns: dict[str, int] = defaultdict(int)
        self.edge_hold_error = Samples(seed=sample_seed)
        self.arrival_lateness = Samples(seed=sample_seed)
        self.poll_lateness = Samples(seed=sample_seed)
        self.cloud_availability_changes: list[dict] = []
        self.cloud_counters = CloudCounters()  # in flight, peak, late (benchmark counters)
        if cloud is not None:
            cloud.attach(self)

    # ------------------------------------------------------------------ lifecycle
    async def start(self) -> "AnalyticsDispatcher":
        """Bind to the running event loop and start the edge loop (and the cloud pool, if not started)."""
        if self._loop is not None:
            raise RuntimeError(f"dispatcher {self.edge_id} is already started")
        self._loop = asyncio.get_running_loop()
        self._wake = asyncio.Event()
        self._idle_event = asyncio.Event()
        if self.cloud is not None:
            self._owns_cloud = not self.cloud.started
            await self.cloud.start(self.clock)
            if not self.cloud.available:
                self.on_cloud_availability(False)
        self.started_ms = max(0.0, self.clock.now_ms())  # a clock may start in the future (a shared run origin)
        self._edge_task = self._loop.create_task(self._edge_loop())
        return self

    def start_background(self) -> "AnalyticsDispatcher":
        """Start on a private event-loop thread (for synchronous callers); returns self."""
        self._thread = _LoopThread(f"dispatcher-{self.edge_id}")
        self._thread.run(self.start(), timeout=60)
        return self

    def finish_background(self, drain_timeout_s: float = 10.0) -> dict:
        """:meth:`finish` from synchronous code (after :meth:`start_background`); stops the loop thread."""
        if self._thread is None:
            raise RuntimeError("finish_background() needs start_background()")
        async def finish_and_close() -> dict:
            report = await self.finish(drain_timeout_s)
            if self._owns_cloud:
                report["cloud"] = self.cloud.report()
                await self.cloud.close()
            return report

        try:
            return self._thread.run(finish_and_close(), timeout=drain_timeout_s + 30)
        finally:
            self._thread.stop()

    # ------------------------------------------------------------------ submission (any thread)
    def submit(self, drone: str, model: str, payload: Any = None, arrival_ms: float | None = None) -> int:
        """Hand a task to the scheduler: ``model`` on a frame of ``drone``. Thread-safe and non-blocking.

        ``payload``: the frame (ObjectRef on the same node, ndarray, JPEG bytes; ignored by emulated executors).
        ``arrival_ms``: arrival on this dispatcher's clock (default: now); the deadline is arrival + the model's
        ``deadline_ms``. Returns the task id. Raises KeyError for a model outside the workload and RuntimeError
        after :meth:`finish` or before :meth:`start`.
        """
        profile = self.workload[model]  # KeyError naming the model and the workload's models
        if self._loop is None or self._stopping:
            raise RuntimeError(f"dispatcher {self.edge_id} is not running (submit before start or after finish)")
        now = self.clock.now_ms()
        arrival = now if arrival_ms is None else float(arrival_ms)
        with self._lock:
            task = AnalyticsTask(next(self._ids), drone, model, arrival, arrival + profile.deadline_ms, payload)
            self._tasks[task.task_id] = task
            self._pending.add(task.task_id)
            self.submitted += 1
        self._call_on_loop(self._on_arrival, task)
        return task.task_id

    def _call_on_loop(self, fn, *args) -> None:
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is self._loop:
            fn(*args)
        else:
            self._loop.call_soon_threadsafe(fn, *args)

    # ------------------------------------------------------------------ policy calls (on the loop)
    #: policy calls that decide something (their latency is the headline ``decision_us``); ``cloud_admit`` and
    #: ``next_poll_ms`` are queries, timed per call only
    DECISION_CALLS = ("submit", "next_edge_task", "on_edge_done", "poll", "on_cloud_done", "on_cloud_availability")

    def _policy(self, name: str, fn, *args):
        t0 = time.perf_counter_ns()
        c0 = time.thread_time_ns()
        with self._lock:
            out = fn(*args)
        us = (time.perf_counter_ns() - t0) / 1000.0
        self.policy_cpu_ns[name] += time.thread_time_ns() - c0  # CPU of this thread: the policy's own work
        if name in self.DECISION_CALLS:
            self.decision_us.add(us)
        self.decision_by_call[name].add(us)
        return out

    def _safe(self, name: str, default: Any, *args, about: str = ""):
        """``self.policy.<name>(*args)`` through :meth:`_policy`; an exception is recorded as a policy error and
        ``default`` returned (a buggy policy must not stop the dispatcher)."""
        try:
            return self._policy(name, getattr(self.policy, name), *args)
        except Exception as e:
            self._policy_error(f"{name}({about}) raised {type(e).__name__}: {e}")
            return default

    def _on_arrival(self, task: AnalyticsTask) -> None:
        now = self.clock.now_ms()
        self.arrival_lateness.add(now - task.arrival_ms)
        if task.state is not TaskState.PENDING:
            return
        decisions = self._safe("submit", _FAILED, task, now, about=f"#{task.task_id}")
        if decisions is _FAILED:
            self._finish(task, TaskState.FAILED, None, f"scheduler error in submit: {self.policy_errors[-1]}")
            return
        self._after_policy(decisions)

    def _after_policy(self, decisions: Iterable[Decision] | None) -> None:
        self._apply(decisions)
        self._rearm_poll()
        self._wake.set()

    def _apply(self, decisions: Iterable[Decision] | None) -> None:
        for d in decisions or ():
            t = d.task
            if self._tasks.get(t.task_id) is not t and t.task_id not in self._pending:
                self._policy_error(f"decision {d.kind} about an unknown task #{t.task_id}")
                continue
            if t.state is not TaskState.PENDING:
                if not self._closing:  # at the end of the run finish() has ended what the policy still held
                    self._policy_error(f"decision {d.kind} about task #{t.task_id}, already {t.state.value}")
                continue
            if t.tier is not None:
                self._policy_error(f"decision {d.kind} about task #{t.task_id}, already running on the {t.tier}")
                continue
            if d.kind == "drop":
                self._finish(t, d.state, None, d.reason)
            else:
                self._send_cloud(t, d.reason)

    def cloud_admits(self, task: AnalyticsTask, now_ms: float) -> bool:
        """Whether the policy still admits ``task`` to the cloud at ``now_ms`` (ms on the run's clock): its
        ``cloud_admit``; False when the policy raises (counted as a policy error). The cloud pool asks it
        before it retries a task on another executor."""
        return bool(self._safe("cloud_admit", False, task, now_ms, about=f"#{task.task_id}"))

    def _admit_by(self, task: AnalyticsTask, now_ms: float) -> float | None:
        return admit_by_time(lambda t: self.cloud_admits(task, t), now_ms, task.deadline_ms)

    def _send_cloud(self, task: AnalyticsTask, reason: str) -> None:
        now = self.clock.now_ms()
        if self._closing:  # after the in-flight sweep of finish(): it would never come back
            self._not_sent(task, f"{reason}; run ended")
            return
        if self.cloud is None or not self.cloud.available:
            self._not_sent(task, f"{reason}; cloud unavailable")
            return
        admit_by = self._admit_by(task, now)
        if admit_by is None:
            self._not_sent(task, f"{reason}; cloud re-check failed before sending")
            return
        task.tier = "cloud"
        task.start_ms = now
        task.reason = reason
        if not self.cloud.send(self, task, admit_by, now):
            task.tier = None
            self._not_sent(task, f"{reason}; cloud unavailable")
        else:
            self.cloud_counters.on_send(now)

    def _not_sent(self, task: AnalyticsTask, reason: str) -> None:
        """A task the policy sent to the cloud is dropped (DROPPED_TIME) before it left the edge; the policy hears
        of it through ``on_cloud_done`` (latency 0), like a refusal at the executor."""
        self._finish(task, TaskState.DROPPED_TIME, None, reason, notify=False)
        decisions = self._safe("on_cloud_done", [], task, self.clock.now_ms(), 0.0, about=f"#{task.task_id}")
        self._notify(task)
        self._apply(decisions)

    def on_cloud_reply(self, task: AnalyticsTask, reply: dict, latency_ms: float, executor: str | None) -> None:
        """The cloud pool's callback with a reply (or a failure) for ``task``: ``reply`` is the executor's
        ``{"ok": bool, "result": ..., "error": str}`` (``"failed": True``: the pool gave up on it), ``latency_ms``
        the round trip on the run's clock (ms), ``executor`` the name of the executor that answered (None: no
        reply). Sets the task's terminal state, then tells the policy (``on_cloud_done``). A task that is no longer
        PENDING is ignored. Call it on the dispatcher's event loop."""
        if task.state is not TaskState.PENDING:
            return
        now = self.clock.now_ms()
        if reply.get("ok"):
            state = TaskState.DONE_ON_TIME if now <= task.deadline_ms else TaskState.DONE_LATE
            task.result = reply.get("result")
            self._finish(task, state, "cloud", task.reason or "cloud", notify=False, end_ms=now)
        elif reply.get("failed") or not str(reply.get("error", "")).startswith("cloud re-check"):
            self._finish(task, TaskState.FAILED, "cloud", reply.get("error") or "cloud failure", notify=False,
                         end_ms=now)
        else:
            self._finish(task, TaskState.DROPPED_TIME, "cloud", reply["error"], notify=False, end_ms=now)
        self.cloud_counters.on_end(task, now)
        decisions = self._safe("on_cloud_done", [], task, now, latency_ms, about=f"#{task.task_id}")
        self._notify(task)
        self._after_policy(decisions)

    def on_cloud_availability(self, available: bool) -> None:
        """The cloud pool's callback when the cloud became unavailable (no executor alive) or available again:
        recorded in :attr:`cloud_availability_changes` and passed to the policy's ``on_cloud_availability``, whose
        decisions are applied. Call it on the dispatcher's event loop."""
        now = self.clock.now_ms()
        self.cloud_availability_changes.append({"at_s": now / 1000.0, "available": available})
        decisions = self._safe("on_cloud_availability", [], available, now)
        if self._wake is not None:
            self._after_policy(decisions)
        else:
            self._apply(decisions)

    def _rearm_poll(self) -> None:
        if self._closing:
            return
        t = self._safe("next_poll_ms", None)
        if t == self._poll_at and self._poll_handle is not None:
            return
        if self._poll_handle is not None:
            self._poll_handle.cancel()
            self._poll_handle = None
        self._poll_at = t
        if t is not None:
            self._poll_handle = self._loop.call_at(self.clock.loop_time(self._loop, t), self._on_poll, t,
                                                   self.clock.now_ms())

    def _on_poll(self, due_ms: float, armed_ms: float) -> None:
        self._poll_handle = None
        self._poll_at = None
        now = self.clock.now_ms()
        # the timer's own lateness: a poll armed for a time already past (a policy whose triggers moved earlier,
        # e.g. after its latency estimate grew) is due when armed, not at that past time
        self.poll_lateness.add(now - max(due_ms, armed_ms))
        decisions = self._safe("poll", [], now)
        self._after_policy(decisions)

    def _policy_error(self, msg: str) -> None:
        self.policy_errors.append(msg)
        log.error("analytics scheduler %s on %s: %s", self.policy.name, self.edge_id, msg)

    # ------------------------------------------------------------------ the edge
    async def _edge_loop(self) -> None:
        while not self._closing:
            self._wake.clear()
            now = self.clock.now_ms()
            task, decisions = self._safe("next_edge_task", (None, []), now)
            self._apply(decisions)
            self._rearm_poll()
            if task is None:
                if self._stopping and not self._pending:
                    return
                await self._wake.wait()
                continue
            if task.state is not TaskState.PENDING:
                self._policy_error(f"next_edge_task returned task #{task.task_id}, already {task.state.value}")
                continue
            task.tier, task.start_ms = "edge", self.clock.now_ms()
            t0 = time.monotonic()
            error = None
            try:
                task.result, intended = await self.edge.run(task, self.workload, self.edge_id)
            except asyncio.CancelledError:
                raise
            except Exception as e:
                error, intended = f"edge execution failed: {type(e).__name__}: {e}", None
            exec_ms = (time.monotonic() - t0) * 1000.0
            self.edge_busy_ms += exec_ms
            if intended is not None:
                self.edge_hold_error.add(exec_ms - intended)
            now = self.clock.now_ms()
            if error is not None:
                self._finish(task, TaskState.FAILED, "edge", error, notify=False, end_ms=now)
            else:
                self._finish(task, TaskState.DONE_ON_TIME if now <= task.deadline_ms else TaskState.DONE_LATE,
                             "edge", task.reason or "edge", notify=False, end_ms=now)
            decisions = self._safe("on_edge_done", [], task, now, exec_ms, about=f"#{task.task_id}")
            self._notify(task)
            self._apply(decisions)
            self._rearm_poll()

    # ------------------------------------------------------------------ terminal states
    def _finish(self, task: AnalyticsTask, state: TaskState, tier: str | None, reason: str,
                notify: bool = True, end_ms: float | None = None) -> None:
        """Give ``task`` its terminal ``state``. ``end_ms`` is the clock reading (ms) the caller judged the deadline
        against, so that ``end_ms <= deadline_ms`` exactly when the state is DONE_ON_TIME; None reads the clock."""
        if task.state is not TaskState.PENDING:
            self._policy_error(f"task #{task.task_id} would end twice ({task.state.value}, then {state.value})")
            return
        task.state = state
        if tier is not None:
            task.tier = tier
        task.reason = reason
        task.end_ms = self.clock.now_ms() if end_ms is None else end_ms
        profile = self.workload[task.model]
        u = task_utility(task, profile)
        self.utility += u
        self.utility_by_model[task.model] += u
        self.count_by_model[task.model] += 1
        if state is TaskState.DONE_ON_TIME:
            self.ontime_by_model[task.model] += 1
        charged = state in _DONE_STATES or state is TaskState.FAILED
        task.utility, task.cost = u, 0.0  # on the task too: its record carries them (the recording's tally)
        if charged and task.tier == "cloud":
            task.cost = profile.cloud_cost
            self.cloud_cost += profile.cloud_cost
        elif charged and task.tier == "edge":
            task.cost = profile.edge_cost
            self.edge_cost += profile.edge_cost
        self.states[state.value] += 1
        self.tiers[task.tier or "none"] += 1
        if state not in _DONE_STATES:
            self.reasons[f"{state.value}: {_reason_key(reason)}"] += 1
        with self._lock:
            self._pending.discard(task.task_id)
            if not self.keep_tasks:
                self._tasks.pop(task.task_id, None)
        if notify:
            self._notify(task)
        if self._stopping and not self._pending and self._idle_event is not None:
            self._idle_event.set()

    def _notify(self, task: AnalyticsTask) -> None:
        """``on_result(task)`` (once per task, in its terminal state), then release the frame (payload)."""
        if self.on_result is not None:
            try:
                self.on_result(task)
            except Exception:  # a consumer's bug must not stop the dispatcher
                log.exception("on_result callback failed for task #%s", task.task_id)
        task.payload = None

    # ------------------------------------------------------------------ end of run
    async def finish(self, drain_timeout_s: float = 10.0) -> dict:
        """Stop accepting tasks, let the queued and in-flight ones finish (up to ``drain_timeout_s`` s), then end
        what is left: tasks the policy still holds become DROPPED_TIME ("run ended"), cloud tasks still in flight
        FAILED ("run ended while in flight"); a task running on the edge is waited for (up to 5 s more). Returns
        :meth:`report`."""
        self._stopping = True
        self._wake.set()
        if self._pending:
            self._idle_event.clear()
            try:
                await asyncio.wait_for(self._idle_event.wait(), drain_timeout_s)
            except asyncio.TimeoutError:
                pass
        self._closing = True  # the edge loop takes no new task, no timer is armed, no task leaves for the cloud
        if self._poll_handle is not None:
            self._poll_handle.cancel()
            self._poll_handle = None
        held = self._safe("held_tasks", [])
        for t in held:
            if t.state is TaskState.PENDING and t.tier is None:
                self._finish(t, TaskState.DROPPED_TIME, None, "run ended while held by the scheduler")
        if self.cloud is not None:
            self.cloud.fail_in_flight(self, "run ended while in flight on the cloud")
        if self._pending and any(t.tier == "edge" for t in self._pending_tasks()):
            self._idle_event.clear()
            try:  # the edge runs at most one task: wait for it (bounded by its hold)
                await asyncio.wait_for(self._idle_event.wait(), 5.0)
            except asyncio.TimeoutError:
                pass
        for t in self._pending_tasks():  # neither terminal nor held: counted as a policy error, never lost
            self._policy_error(f"task #{t.task_id} was neither terminal nor held at the end of the run")
            self._finish(t, TaskState.FAILED if t.tier else TaskState.DROPPED_TIME, None,
                         "run ended; the scheduler did not report the task as held")
        self._closed = True
        if self._poll_handle is not None:
            self._poll_handle.cancel()
        if self._edge_task is not None:
            self._wake.set()
            self._edge_task.cancel()
            try:
                await self._edge_task
            except (asyncio.CancelledError, Exception):
                pass
        self.finished_ms = self.clock.now_ms()
        return self.report()

    @property
    def running(self) -> bool:
        """True from :meth:`start` until :meth:`finish` has ended every task (then :meth:`finish` is not needed)."""
        return self._loop is not None and not self._closed

    def _pending_tasks(self) -> list[AnalyticsTask]:
        with self._lock:
            return [self._tasks[i] for i in sorted(self._pending) if i in self._tasks]

    # ------------------------------------------------------------------ results
    def tasks(self) -> list[AnalyticsTask]:
        """Every task submitted (when ``keep_tasks``), in submission order."""
        with self._lock:
            return list(self._tasks.values())

    def report(self, samples: bool = False) -> dict:
        """Counters and statistics of the run so far (see the benchmark's JSON for the field meanings).

        ``samples=True`` adds the raw decision-latency and timing samples (for pooling across dispatchers)."""
        with self._lock:
            pending = len(self._pending)
        end = self.finished_ms if self.finished_ms is not None else self.clock.now_ms()
        dur = max(1e-9, end - (self.started_ms or 0.0))
        total = self.submitted
        done_on_time = self.states.get(TaskState.DONE_ON_TIME.value, 0)
        drops = {s.value: self.states.get(s.value, 0) for s in (*DROP_STATES, TaskState.FAILED)}
        out = {
            "edge_id": self.edge_id, "scheduler": self.policy.name, "submitted": total,
            "terminal": sum(self.states.values()), "pending": pending,
            "states": {s.value: self.states.get(s.value, 0) for s in TaskState if s is not TaskState.PENDING},
            "tiers": dict(self.tiers), "on_time_rate": done_on_time / total if total else 0.0,
            "utility": self.utility, "utility_by_model": dict(self.utility_by_model),
            "tasks_by_model": dict(self.count_by_model), "on_time_by_model": dict(self.ontime_by_model),
            "cloud_cost": self.cloud_cost, "edge_cost": self.edge_cost, "drops": drops,
            "drop_reasons": dict(self.reasons), "edge_busy_ms": self.edge_busy_ms, "duration_ms": dur,
            "edge_utilisation": self.edge_busy_ms / dur,
            "decision_us": {**self.decision_us.summary(),
                            "by_call": {k: v.summary() for k, v in self.decision_by_call.items()}},
            "policy_cpu_s": {k: v / 1e9 for k, v in self.policy_cpu_ns.items()},
            "timing_ms": {"edge_hold_error": self.edge_hold_error.summary(),
                          "arrival_lateness": self.arrival_lateness.summary(),
                          "poll_lateness": self.poll_lateness.summary()},
            "cloud_availability_changes": list(self.cloud_availability_changes),
            "counters": {**dict(self.policy.counters), **self.cloud_counters.summary()},
            "accounting": {"submitted": total, "terminal": sum(self.states.values()), "pending": pending,
                           "policy_errors": len(self.policy_errors), "errors": self.policy_errors[:20]},
            "edge_executor": self.edge.describe(),
        }
        if samples:
            out["samples"] = {"decision_us": list(self.decision_us.values),
                              "edge_hold_error_ms": list(self.edge_hold_error.values),
                              "arrival_lateness_ms": list(self.arrival_lateness.values),
                              "poll_lateness_ms": list(self.poll_lateness.values)}
        return out
