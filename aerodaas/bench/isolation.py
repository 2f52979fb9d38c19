"""A policy run in its own fresh process, with secret draws: what the non-anticipation test needs to be sound.

Why: the harness drew every edge and cloud time from ``seeded_rng(seed, kind, edge_id, task_id)`` with a
small public seed and ran the policy in its own process. A policy could then walk the call stack to the harness
and recompute a draw from its seed, infer the seed from the first revealed latency (the seeding scheme is public),
or cache latencies across runs of one process — and pass the cut test (0 of 22 cuts caught).

Here, by construction:

* :func:`secret_seed` gives a 256-bit seed from the OS's entropy (:func:`secrets.token_bytes`); the harness accepts
  it as its ``seed`` (``seeded_rng`` hashes its keys with BLAKE2b, bytes included), so no draw can be recomputed
  or the seed searched for. The caller records it only after the run.
* :class:`IsolatedPolicy` runs the policy in a new process for every run, forked from a ``forkserver`` that only
  imported the schedulers (:mod:`multiprocessing`; the server never sees a harness, a trace or a seed). The policy
  is built there from its registered name or ``"module:Class"`` (:func:`analytics_scheduler_class`) and the
  workload; it receives only what a dispatcher would give it — each call with its time and the tasks it is about,
  as copies — over a pipe. Its process holds no harness frame, no trace and no draw, and starts with no state of
  an earlier run.

What this does not stop: a policy that reads other processes' memory (``/proc/PID/mem`` of the harness, possible
for a process of the same user where the kernel allows ptrace of non-descendants) or talks to the harness
process by other means. Running the policy as another user or in a sandbox would; the test does not go that far.

The proxy costs one pipe round trip per call (about 0.1 ms): fine for tests, not for the published sweep, which
keeps its reproducible in-process runs (a published, recorded seed).
"""
from __future__ import annotations

import enum
import functools
import multiprocessing
import secrets
import sys
import traceback
import types
from collections import Counter
from typing import Any, Mapping

from aerodaas.schedulers.analytics_base import (AnalyticsScheduler, AnalyticsTask, Decision, TaskState, Workload,
                                                analytics_scheduler_class)

__all__ = ["secret_seed", "IsolatedPolicy", "PolicyProcessError"]

#: the modules the fork server imports before forking policy processes (so each fork starts warm, not with state)
PRELOAD = ("aerodaas.bench.isolation_preload",)


def secret_seed() -> bytes:
    """32 bytes from the OS's entropy source (:func:`secrets.token_bytes`): a seed a policy can neither read nor
    search for."""
    return secrets.token_bytes(32)


class PolicyProcessError(RuntimeError):
    """The policy raised in its process (the message carries its traceback), or its process died."""


class _Call(enum.Enum):
    """What the harness asks the policy process (one per contract method, plus the end-of-run queries)."""

    SUBMIT = "submit"
    NEXT_EDGE_TASK = "next_edge_task"
    ON_EDGE_DONE = "on_edge_done"
    POLL = "poll"
    NEXT_POLL_MS = "next_poll_ms"
    CLOUD_ADMIT = "cloud_admit"
    ON_CLOUD_DONE = "on_cloud_done"
    ON_CLOUD_AVAILABILITY = "on_cloud_availability"
    HELD_TASKS = "held_tasks"
    COUNTERS = "counters"


#: calls that may change the policy's state (and so its next poll time)
_CHANGES = frozenset({_Call.SUBMIT, _Call.NEXT_EDGE_TASK, _Call.ON_EDGE_DONE, _Call.POLL, _Call.ON_CLOUD_DONE,
                      _Call.ON_CLOUD_AVAILABILITY})


def _row(t: AnalyticsTask) -> tuple:
    """The fields of a task a dispatcher shows its policy (not ``payload``, ``result`` or the policy's notes)."""
    return (t.task_id, t.drone, t.model, t.arrival_ms, t.deadline_ms, t.tier, t.state.value, t.reason, t.start_ms,
            t.end_ms)


@functools.cache
def _context() -> Any:
    """The ``forkserver`` multiprocessing context with :data:`PRELOAD` set, made once per process
    (``functools.cache``: a cached factory, no module-level variable rebound with ``global``)."""
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(list(PRELOAD))
    return ctx


def _decisions(ds: list[Decision]) -> list[tuple]:
    return [(d.kind, d.task.task_id, d.reason, d.state.value if d.state is not None else None) for d in ds]


def _serve(conn, ref: str, workload: Workload, options: Mapping[str, Any]) -> None:
    """The policy process: build the policy, then answer calls until the pipe closes. Keeps one task object per id
    (the policy's own, with its notes), updated from the rows the harness sends."""
    try:
        pol = analytics_scheduler_class(ref)(workload, **options)
    except BaseException:
        conn.send(("error", traceback.format_exc(), None))
        return
    conn.send(("ok", pol.name, None))
    tasks: dict[int, AnalyticsTask] = {}

    def task(row: tuple) -> AnalyticsTask:
        tid, drone, model, arr, dl, tier, state, reason, start, end = row
        t = tasks.get(tid)
        if t is None:
            t = tasks[tid] = AnalyticsTask(tid, drone, model, arr, dl)
        t.tier, t.state, t.reason, t.start_ms, t.end_ms = tier, TaskState(state), reason, start, end
        return t

    while True:
        try:
            msg = conn.recv()
        except EOFError:
            return
        call, now, rows, extra, sync = msg
        try:
            for r in sync:
                task(r)
            ts = [task(r) for r in rows]
            out: Any
            if call is _Call.SUBMIT:
                out = _decisions(pol.submit(ts[0], now))
            elif call is _Call.NEXT_EDGE_TASK:
                t, ds = pol.next_edge_task(now)
                out = (None if t is None else t.task_id, _decisions(ds))
            elif call is _Call.ON_EDGE_DONE:
                out = _decisions(pol.on_edge_done(ts[0], now, extra))
            elif call is _Call.POLL:
                out = _decisions(pol.poll(now))
            elif call is _Call.NEXT_POLL_MS:
                out = pol.next_poll_ms()
            elif call is _Call.CLOUD_ADMIT:
                out = bool(pol.cloud_admit(ts[0], now))
            elif call is _Call.ON_CLOUD_DONE:
                out = _decisions(pol.on_cloud_done(ts[0], now, extra))
            elif call is _Call.ON_CLOUD_AVAILABILITY:
                out = _decisions(pol.on_cloud_availability(extra, now))
            elif call is _Call.HELD_TASKS:
                out = [t.task_id for t in pol.held_tasks()]
            else:
                out = dict(pol.counters)
            # the next poll time after a call that may change it, so that the harness's query after the event
            # needs no round trip when nothing changed since (see IsolatedPolicy.next_poll_ms)
            conn.send(("ok", out, pol.next_poll_ms() if call in _CHANGES else None))
        except BaseException:
            conn.send(("error", traceback.format_exc(), None))
            return


class IsolatedPolicy(AnalyticsScheduler):
    """The policy registered as ``ref`` (or ``"module.path:Class"``), built with ``options``, run in a fresh
    process (see the module docstring) behind the :class:`AnalyticsScheduler` contract: drive it with the
    :class:`aerodaas.bench.harness.Harness` as any policy, then :meth:`close` it (or use it as a context manager).

    Task objects stay the caller's: the process works on copies, and a decision names a task by its id, mapped back
    here. The changes the harness makes to a task (tier, state, reason, start and end) reach the process with the
    next call. Raises :class:`PolicyProcessError` when the policy raises (its traceback in the message) or its
    process dies; ValueError-free otherwise (a bad name or option surfaces as that error)."""

    name = "ISOLATED"

    def __init__(self, ref: str, workload: Workload, options: Mapping[str, Any] | None = None) -> None:
        super().__init__(workload)
        ctx = _context()
        self._conn, child = ctx.Pipe()
        self._next_poll: float | None = None
        self._proc = ctx.Process(target=_serve, args=(child, ref, workload, dict(options or {})), daemon=True)
        # multiprocessing re-imports the caller's main module in every child (spawn.get_preparation_data): under
        # pytest that is pytest, ~0.3 s a run, and for a script it is the harness's own code. Hidden while starting
        # (the harness is single-threaded), the child starts from the fork server's imports alone.
        main = sys.modules["__main__"]
        sys.modules["__main__"] = types.ModuleType("__main__")
        try:
            self._proc.start()
        finally:
            sys.modules["__main__"] = main
        child.close()
        self.name = self._answer()
        self._tasks: dict[int, AnalyticsTask] = {}
        self._dirty: dict[int, AnalyticsTask] = {}
        self._poll_known = False

    # -- the pipe
    def _answer(self, changes: bool = False):
        try:
            status, value, next_poll = self._conn.recv()
        except (EOFError, OSError) as e:
            raise PolicyProcessError(f"the policy process ended (exit code {self._proc.exitcode}): {e}") from None
        if status != "ok":
            raise PolicyProcessError(f"the policy raised in its process:\n{value}")
        if changes:
            self._next_poll = next_poll
        return value

    def _call(self, call: _Call, now_ms: float, tasks: tuple = (), extra: Any = None):
        for t in tasks:
            self._tasks[t.task_id] = t
            self._dirty.pop(t.task_id, None)
        sync = [_row(t) for t in self._dirty.values()]
        self._dirty.clear()
        try:
            self._conn.send((call, float(now_ms), [_row(t) for t in tasks], extra, sync))
        except OSError as e:  # the process ended (it raised earlier, or died)
            raise PolicyProcessError(f"the policy process ended (exit code {self._proc.exitcode}): {e}") from None
        if call in _CHANGES or sync:  # a pure query leaves the known poll time as it was, unless tasks changed
            self._poll_known = call in _CHANGES
        return self._answer(call in _CHANGES)

    def _back(self, rows: list[tuple]) -> list[Decision]:
        out = []
        for kind, tid, reason, state in rows:
            t = self._tasks[tid]
            self._dirty[tid] = t  # the harness acts on it after this call
            out.append(Decision(kind, t, reason, TaskState(state) if state is not None else None))
        return out

    # -- the contract
    def submit(self, task: AnalyticsTask, now_ms: float) -> list[Decision]:
        return self._back(self._call(_Call.SUBMIT, now_ms, (task,)))

    def next_edge_task(self, now_ms: float) -> tuple[AnalyticsTask | None, list[Decision]]:
        task, decisions = self._pop_edge(now_ms)
        if task is not None:
            self.edge_running = task
        return task, decisions

    def _pop_edge(self, now_ms: float) -> tuple[AnalyticsTask | None, list[Decision]]:
        """The policy process's choice of the next edge task (its own edge bookkeeping stays there)."""
        tid, rows = self._call(_Call.NEXT_EDGE_TASK, now_ms)
        task = None if tid is None else self._tasks[tid]
        if task is not None:
            self._dirty[tid] = task
        return task, self._back(rows)

    def on_edge_done(self, task: AnalyticsTask, now_ms: float, exec_ms: float) -> list[Decision]:
        self.edge_running = None
        return self._back(self._call(_Call.ON_EDGE_DONE, now_ms, (task,), float(exec_ms)))

    def poll(self, now_ms: float) -> list[Decision]:
        return self._back(self._call(_Call.POLL, now_ms))

    def next_poll_ms(self) -> float | None:
        """The policy's answer after its last state-changing call, sent with that call's answer, while the harness
        has changed no task since (a changed task is shown to the policy first, by a real query)."""
        if self._poll_known and not self._dirty:
            return self._next_poll
        return self._call(_Call.NEXT_POLL_MS, 0.0)

    def cloud_admit(self, task: AnalyticsTask, now_ms: float) -> bool:
        return self._call(_Call.CLOUD_ADMIT, now_ms, (task,))

    def on_cloud_done(self, task: AnalyticsTask, now_ms: float, latency_ms: float) -> list[Decision]:
        return self._back(self._call(_Call.ON_CLOUD_DONE, now_ms, (task,), float(latency_ms)))

    def on_cloud_availability(self, available: bool, now_ms: float) -> list[Decision]:
        self.cloud_available = available
        return self._back(self._call(_Call.ON_CLOUD_AVAILABILITY, now_ms, (), bool(available)))

    def held_tasks(self) -> list[AnalyticsTask]:
        return [self._tasks[tid] for tid in self._call(_Call.HELD_TASKS, 0.0)]

    @property
    def counters(self):  # type: ignore[override]  # the policy's, read from its process

        if getattr(self, "_conn", None) is None or self._conn.closed:
            return Counter(self.__dict__.get("_final_counters", {}))
        return Counter(self._call(_Call.COUNTERS, 0.0))

    @counters.setter
    def counters(self, value) -> None:  # the base class's constructor sets an empty Counter
        self.__dict__["_final_counters"] = dict(value)

    # -- the process
    def close(self) -> None:
        """End the policy's process (it is never reused: the next run starts a fresh one)."""
        if getattr(self, "_conn", None) is not None and not self._conn.closed:
            try:
                self.__dict__["_final_counters"] = dict(self.counters)
            except PolicyProcessError:
                pass
            self._conn.close()
        self._proc.join(timeout=30)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join()

    def __enter__(self) -> "IsolatedPolicy":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
