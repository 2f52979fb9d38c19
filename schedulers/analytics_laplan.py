"""LAPLAN: EVPLAN's expected-value cloud option with an edge plan that looks ahead over the predicted arrivals.

Why. The exact offline optimum of the HEAVY workload at 3 drones per edge (:mod:`aerodaas.bench.bound`, method
``exact``: the non-preemptive max-gain edge schedule on the same trace and draws) runs almost only the two long,
high-gain models on the edge — DEO (739 ms, gain over its cloud fallback 204) and CD (563 ms, gain 148): on seed 0,
420 DEO and 324 CD of 744 edge runs, the edge busy 100 % of the time. EVPLAN ran 231 DEO and 209 CD, filling the
rest with short low-gain models (DEV, BP, HV: gain 25-38 for 172-244 ms). The reason is its plan's horizon: it
plans over the tasks that have arrived. When the edge frees and no DEO/CD is waiting, it starts a BP (244 ms); a
DEO arriving 50 ms later can then no longer start by its latest start (deadline 950 - 739 = arrival + 211 ms), and
its cloud trigger (arrival + 108 ms) sends it to the cloud. The drones' frames are periodic (one 1-frame batch per
drone per second, :func:`aerodaas.bench.workload.make_trace`, the reference's mock client), so the next
arrivals can be predicted from the ones seen.

Rules (times ms; EVPLAN's expected cloud value ``V`` and triggers, see :mod:`.analytics_evplan`, with two
changes: the observed round-trip / profile ratios are pooled over all models (``pool_models``, default on: one
model's few samples no longer decide its ``V``), and a task is acted on ``release_early_ms`` before its trigger,
default DEMS's 50 ms):

* Arrival prediction, learned online (by default, ``arrivals="burst"``, the burst/idle model described at the end of
  this bullet; with ``arrivals="last"``, the earlier default, as follows): per drone, the
  period is the gap between its last two frames (tasks of one frame share an arrival time), or with ``gap_window`` k > 1 the median of its last k gaps (bursty video: a burst's
  gap rather than the silence before it or a flush's 2 ms), and the frame's models are the last frame's. The frames of the next
  ``horizon_ms`` (default 2,000) are predicted at ``last + k * period``; a frame overdue by more than a tenth of
  the period stops the drone's predictions until it sends again (a stopped or irregular drone is not waited for).
  With ``arrivals="burst"`` (the default) the burst/idle model of :class:`.analytics_arrivals.BurstArrivalPredictor`
  predicts instead (the burst's gap on the drone's phase grid, a flush not moving the phase, the burst's end, and for
  heavy-tailed gaps one frame at the gap's quantile given the wait, its gain in the plan weighted by that chance).
* Edge plan: the exact max-gain schedule with release times (:func:`.single_machine.max_gain_schedule`) over the
  pool (release: when the edge is free) and the predicted tasks (release: their predicted arrival), each with
  EVPLAN's gain (edge utility - max(0, V); a predicted task's V at its arrival). Processing times are the profile's
  x the mean observed edge ratio (chains add means). Each task enters the plan as one variant per on-time level
  of ``edge_levels`` (default 0.7 ... 0.995): its deadline tightened by the tail ``p * (q - mean)``, ``q`` the
  observed ratio at that level, and its gain weighted by that chance; the DP picks at most one variant per task.
* The edge starts the plan's first task if it is a real one; if the plan waits for a predicted task, the edge
  stays idle and the policy re-plans at that time (:meth:`next_poll_ms`) or at the next event.
* At a task's cloud trigger (EVPLAN's): committed to the edge if the plan runs it (any start), else sent to the
  cloud if ``V > 0``, else kept as an edge-only candidate, dropped when it no longer fits.

The plan is cached while nothing unpredicted happens (see :meth:`LaPlan.submit`): an arrival that matches a
predicted task (same drone and model, within ``same_frame_ms`` = 50 ms of the predicted frame time) takes its
twin's place; any other arrival, a lost task, a mode change or the edge's state re-plans. This is an
approximation: a task that arrives up to 50 ms early has an earlier deadline than its twin had, and the cloud
fallbacks ``V`` of the open tasks change with time and with each cloud completion without a re-plan; measured on
the HEAVY sweep cells it moved utility by < 0.1 % and cut the plans computed per second from 10.7 to 3.8 per edge.

The edge state a plan assumed holds for ``replan_tolerance_ms`` (default 2 ms) past the instant it planned from (a
running task's expected end, or an idle edge's first start), but never longer than the plan's slack (the least, over
its tasks, of latest end - planned end): a plan is not kept once a planned task, started that much later, would no
longer end by its chosen variant's latest end; when the first task starts late, the kept rest of the plan moves as
much later. Why: on the Ray runtime the calls a dispatcher makes for one event (an arrival's ``submit``, the poll
timer, ``next_edge_task`` from the edge loop) reach the policy a fraction of a ms to a few ms apart on the wall
clock, and with no tolerance each found the plan's instant just passed and planned again: 4,401 plans against the
harness's 3,178 on the same 80-drone trace (2026-11-24), each ~1 ms of CPU, which made the 80-drone emulation late.
In the harness, where one event's calls share one time, it moved the 5-seed mean utility at 80 drones by under
0.01 % (single seeds by up to 0.09 %) on periodic and realistic traces (docs/results/schedulers.md).

There is no ``commit_horizon_ms`` (GAINPLAN/EVPLAN's): at its trigger a task is committed to the edge exactly
when the plan runs it, wherever it stands.
"""
from __future__ import annotations

import math
from collections import deque
from typing import NamedTuple

import numpy as np

from aerodaas.schedulers.analytics_arrivals import ArrivalPredictor, BurstArrivalPredictor
from aerodaas.schedulers.analytics_base import AnalyticsTask, Decision, Workload
from aerodaas.schedulers.analytics_dems import JIT_EARLY_MS
from aerodaas.schedulers.analytics_evplan import EvPlan
from aerodaas.schedulers.analytics_gainplan import COMMITTED, EDGE_ONLY, OPEN
from aerodaas.schedulers import single_machine_jit
from aerodaas.schedulers.single_machine import SolveCounts, max_gain_schedule_arrays

__all__ = ["LaPlan", "ArrivalPredictor", "EDGE_LEVELS"]

#: on-time chances at which a planned edge task's expected gain is evaluated (its start-time variants)
EDGE_LEVELS = (0.7, 0.8, 0.9, 0.95, 0.98, 0.995)


class _CachedPlan(NamedTuple):
    """LAPLAN's plan as last computed (:meth:`LaPlan.schedule`) or kept after a start (:meth:`LaPlan._pop_edge`)."""

    key: tuple                 # (version, edge idle) it was made for
    plan: list                 # [(task key, planned start ms)]
    first_wake: float | None   # when to re-plan if its first task is a predicted one that has not come (ms)
    valid_until: float         # ms: the edge's planned state plus the tolerance (module docstring)
    slack: float               # ms: how late every planned task may still start and end by its latest end


class LaPlan(EvPlan):
    """LAPLAN (see the module docstring). Options: ``horizon_ms`` (lookahead, default 2,000 ms; 0 = no
    prediction), ``edge_levels`` (on-time chances of the edge-time variants, each in (0, 1]), ``pool_models``
    (default True), ``release_early_ms`` (default 50), ``replan_tolerance_ms`` (default 2, in [0, 100]),
    ``gap_window`` (``arrivals="last"`` only; default 1: the period is the last frame gap; k: the median of the last
    k, see the module),
    ``arrivals`` (``"burst"``, the default, chosen on held-out seeds: the burst/idle and hazard model
    :class:`.analytics_arrivals.BurstArrivalPredictor`; ``"last"``: the last-gap predictor
    :class:`.analytics_arrivals.ArrivalPredictor`, the default before, with which the published periodic and
    realistic sweeps and the Ray runtime results were made), ``burst_quantile`` (its ``quantile``, default 0.5), and
    EVPLAN's ``window``, ``tolerance``, ``estimator`` and ``edge_quantile`` (admission only). Terminal states as
    GAINPLAN's. Raises ValueError for out-of-range options and for ``commit_horizon_ms``, which LAPLAN does not
    have."""

    name = "LAPLAN"
    options = tuple(o for o in EvPlan.options if o != "commit_horizon_ms") + (
        "horizon_ms", "edge_levels", "pool_models", "release_early_ms", "replan_tolerance_ms", "gap_window", "arrivals",
        "burst_quantile")

    def __init__(self, workload: Workload, *, horizon_ms: float = 2000.0,
                 edge_levels: tuple[float, ...] = EDGE_LEVELS, pool_models: bool = True,
                 release_early_ms: float = JIT_EARLY_MS, replan_tolerance_ms: float = 2.0, gap_window: int = 1,
                 arrivals: str = "burst", burst_quantile: float = 0.5, **kw) -> None:
        if "commit_horizon_ms" in kw:
            raise ValueError(f"LAPLAN has no commit_horizon_ms (got {kw['commit_horizon_ms']!r}): its plan decides "
                             "which tasks are committed to the edge")
        super().__init__(workload, commit_horizon_ms=math.inf, **kw)
        if not horizon_ms >= 0:
            raise ValueError(f"horizon_ms must be >= 0, got {horizon_ms!r}")
        levels = tuple(sorted(float(q) for q in edge_levels))
        if not levels or not all(0 < q <= 1 for q in levels):
            raise ValueError(f"edge_levels must be probabilities in (0, 1], got {edge_levels!r}")
        self.horizon_ms, self.edge_levels = float(horizon_ms), levels
        if arrivals == "last":
            self.arrivals: ArrivalPredictor = ArrivalPredictor(gap_window=gap_window)
        elif arrivals == "burst":
            if gap_window != 1:
                raise ValueError(f"gap_window={gap_window!r} is for arrivals='last' (pass it too); the burst "
                                 "predictor, the default, keeps its own")
            self.arrivals = BurstArrivalPredictor(quantile=burst_quantile)
        else:
            raise ValueError(f"arrivals must be 'last' or 'burst', got {arrivals!r}")
        self.pool_models = bool(pool_models)
        if not 0 <= release_early_ms:
            raise ValueError(f"release_early_ms must be >= 0, got {release_early_ms!r}")
        self.jit_early_ms = float(release_early_ms)
        if not 0 <= replan_tolerance_ms <= 100:
            raise ValueError(f"replan_tolerance_ms must be in [0, 100] ms, got {replan_tolerance_ms!r}")
        self.replan_tolerance_ms = float(replan_tolerance_ms)
        self._edge_obs: deque[float] = deque(maxlen=100)
        self._edge_mean = 1.0                                  # mean observed edge run / profile ratio
        self._tails: list[tuple[float, float]] = [(0.0, 1.0)]  # (ratio above the mean, on-time chance) per level
        self._version = 0      # bumped whenever the pool, a mode or the edge changes
        self._cache: _CachedPlan | None = None
        self._wake: float | None = None
        self._first_wake: float | None = None
        self._predicted: dict[tuple, list[float]] = {}  # (drone, model) -> predicted frame times of the plan
        #: model -> [(edge_ms x tail, planned processing ms, chance x benefit - edge cost)] per level (:meth:`_variants`)
        self._vparts: dict[str, list[tuple[float, float, float]]] = {}
        self._plan_index: tuple[list, dict] = ([], {})  # (plan, key -> planned start) of the last plan looked up
        single_machine_jit.warm_up()  # compile or load the planner's kernel now, not on the first decision

    def _ratios(self, model: str) -> list[float]:
        if not self.pool_models:
            return super()._ratios(model)
        if model not in self._sorted:
            self._sorted[model] = sorted(self.pooled) if self.pooled else [1.0]
        return self._sorted[model]

    # -- the plan
    def _parts(self, model: str) -> list[tuple[float, float, float]]:
        """The deadline- and fallback-free parts of a ``model`` task's variants, one per edge-time level:
        ``(edge ms x tail, planned processing ms, chance x benefit - edge cost)``; kept until the edge statistics
        change (:meth:`on_edge_done`)."""
        parts = self._vparts.get(model)
        if parts is None:
            p = self.w[model]
            proc = p.edge_ms * self._edge_mean
            parts = self._vparts[model] = [(p.edge_ms * tail, proc, chance * p.benefit - p.edge_cost)
                                           for tail, chance in self._tails]
        return parts

    def _variants(self, model: str, deadline_ms: float, fallback: float) -> list[tuple[float, float, float]]:
        """``(latest end ms, planned processing ms, expected gain)`` per edge-time level of a task of ``model``:
        ending by ``deadline - p * tail`` at the planned (mean) time, it is on time with the level's chance."""
        # the same float operations in the same order as computing each variant from scratch
        return [(deadline_ms - lead, proc, g - fallback) for lead, proc, g in self._parts(model)]

    def _predicted_fallback(self, model: str) -> float:
        p = self.w[model]
        if not self.cloud_available or p.cloud_utility <= 0:
            return 0.0
        return max(0.0, self.on_time_chance(model, p.deadline_ms) * p.benefit - p.cloud_cost)

    @staticmethod
    def _key(task: AnalyticsTask) -> tuple:
        """A task's identity in a plan: (drone, model, frame time) — the predicted frame's time once it came."""
        return task.notes.get("plan_key") or (task.drone, task.model, task.arrival_ms)

    def schedule(self, now_ms: float) -> list[tuple[tuple, float]]:
        """The current plan: ``[(key, planned start ms)]`` from when the edge is free, keys as :meth:`_key` (a
        predicted task's is its drone, model and predicted frame time). Sets :attr:`_first_wake`: when to re-plan
        if the plan starts with a predicted task that has not come. Cached while nothing changed.

        The DP's instance is built as arrays, one row per task and one column per edge-time level (the variants
        of :meth:`_variants`, from the same :meth:`_parts`), and solved by
        :func:`.single_machine.max_gain_schedule_arrays` — the same plan as the job tuples gave, at a fraction of
        the Python work per plan."""
        key = (self._version, self.edge_running is None)
        if self._cache is not None and self._cache.key == key:
            if now_ms <= self._cache.valid_until:  # the edge's state as planned, or late by less than the slack
                self._first_wake = self._cache.first_wake
                return self._cache.plan
            # why this plan is recomputed although nothing changed (diagnostics: the runtime's wall clock)
            self.counters["plans_edge_overran" if self.edge_running is not None else "plans_start_passed"] += 1
        self._now = now_ms
        free = self._edge_free_at(now_ms)
        rel, dl, fb, wt, parts, keys, wakes, n_pool = self._instance(now_ms, free)
        levels = len(self._tails)
        sched, slack, rows = self._solve(rel, dl, fb, wt, parts, keys, free, n_pool)
        self.counters["plans"] += 1
        plan = [(keys[rows[j // levels]], s) for j, s in sched]
        self._first_wake = None
        if plan and plan[0][0] in wakes:
            self._first_wake = max(plan[0][1], wakes[plan[0][0]])
        # valid while nothing changes and the edge state it assumed holds: the running task not overdue, or (idle)
        # until its first start; either up to replan_tolerance_ms more, but never more than the plan's slack
        # (module docstring)
        at = free if self.edge_running is not None else (plan[0][1] if plan else math.inf)
        self._cache = _CachedPlan(key, plan, self._first_wake, at + self._tolerance(slack), slack)
        return plan

    def _instance(self, now_ms: float, free: float) -> tuple[list, list, list, list, list, list, dict, int]:
        """The plan's rows, the pool's first, then the predicted tasks': release, deadline, cloud fallback, gain
        weight (1 but for a predicted task the predictor is unsure of), variant parts (:meth:`_parts`) and key
        (:meth:`_key`) per task; the predicted tasks' wake times by key; the number of pool rows. Sets
        :attr:`_predicted`."""
        rel, dl, fb, wt, parts, keys = [], [], [], [], [], []
        for t in self.pool:
            rel.append(free)
            dl.append(t.deadline_ms)
            fb.append(max(0.0, self.cloud_value(t, now_ms)) if t.notes.get("mode") == OPEN else 0.0)
            wt.append(1.0)
            parts.append(self._parts(t.model))
            keys.append(self._key(t))
        n_pool = len(keys)
        self._predicted = {}
        wakes = {}
        if self.horizon_ms > 0:
            fbs: dict[str, float] = {}
            for at, drone, m, wake, frame, weight in self.arrivals.predict(now_ms, self.horizon_ms):
                if m not in fbs:
                    fbs[m] = self._predicted_fallback(m)
                k = (drone, m, frame)
                wakes[k] = wake
                self._predicted.setdefault((drone, m), []).append(frame)
                rel.append(max(at, free))
                dl.append(frame + self.w[m].deadline_ms)
                fb.append(fbs[m])
                wt.append(weight)
                parts.append(self._parts(m))
                keys.append(k)
        return rel, dl, fb, wt, parts, keys, wakes, n_pool

    def _solve(self, rel: list, dl: list, fb: list, wt: list, parts: list, keys: list, free: float, n_pool: int
               ) -> tuple[list[tuple[int, float]], float, list[int]]:
        """The max-gain schedule of the rows (:meth:`_instance`): ``(schedule as [(row x levels + level, start)],
        slack ms, the rows it was solved over)``. When more than 64 task groups would be live at once (the compiled
        kernel's limit; a burst of flushed frames), the rows are reduced until they fit instead of running the
        exponential pure-Python DP: the latest half of the predicted tasks first, then the pool's half with the
        least gain (counted: ``plans_reduced``). Without numba the Python DP runs (counted: ``plans_in_python``)."""
        rows = list(range(len(keys)))
        if not rows:
            return [], math.inf, rows
        levels = len(self._tails)
        pa_all = np.array(parts, np.float64)  # (tasks, levels, 3): the same operations as :meth:`_variants`
        rel_a, dl_a, fb_a = np.array(rel, np.float64), np.array(dl, np.float64), np.array(fb, np.float64)
        wt_a = np.array(wt, np.float64)  # x 1.0 is exact: unweighted rows keep their gains bit for bit
        reduced = False
        solves = SolveCounts()  # which DP solved this plan
        while True:
            idx = np.array(rows, np.int64)
            pa = pa_all[idx]
            ids: dict[tuple, int] = {}
            gid = np.array([ids.setdefault(keys[r], len(ids)) for r in rows], np.int64)  # one group per key
            latest, proc = (dl_a[idx][:, None] - pa[:, :, 0]).ravel(), pa[:, :, 1].ravel()
            got = max_gain_schedule_arrays(
                np.repeat(rel_a[idx], levels), latest, proc, ((pa[:, :, 2] - fb_a[idx][:, None]) * wt_a[idx][:, None]).ravel(),
                np.repeat(gid, levels), len(ids), free_at=free, python_fallback=False, counts=solves)
            if got is not None:
                break
            reduced = True
            rows = self._fewer_rows(rows, rel, fb, parts, n_pool)
        if solves.python:  # the slow pure-Python DP ran (numba missing)
            self.counters["plans_in_python"] += 1
        if reduced:
            self.counters["plans_reduced"] += 1
        sched = got[1]
        return sched, min((latest[j] - s - proc[j] for j, s in sched), default=math.inf), rows

    @staticmethod
    def _fewer_rows(rows: list[int], rel: list, fb: list, parts: list, n_pool: int) -> list[int]:
        """``rows`` less the latest-released half of its predicted rows, or, with none left, less the half of its
        pool rows with the least best gain (their top variant's gain less the cloud fallback)."""
        pred = sorted((r for r in rows if r >= n_pool), key=lambda r: (rel[r], r))
        if pred:
            drop = set(pred[len(pred) // 2:])
        else:
            by_gain = sorted(rows, key=lambda r: (max(g for *_, g in parts[r]) - fb[r], -r))
            drop = set(by_gain[:max(1, len(by_gain) // 2)])
        return [r for r in rows if r not in drop]

    def _tolerance(self, slack: float) -> float:
        """How late (ms) the edge may be on a plan of this ``slack`` before it is recomputed: ``replan_tolerance_ms``,
        at most the slack (a plan is never kept once a planned task would no longer end by its latest end)."""
        return min(self.replan_tolerance_ms, max(0.0, slack))

    def _plan(self, start_ms: float) -> list[AnalyticsTask]:
        keys = {k for k, _ in self.schedule(self._now)}
        return [t for t in self.pool if self._key(t) in keys]

    def _planned_start(self, task: AnalyticsTask, now_ms: float) -> float | None:
        plan = self.schedule(now_ms)
        if self._plan_index[0] is not plan:  # index the plan once, not a scan per task (keys are unique in a plan)
            self._plan_index = (plan, {q: s for q, s in reversed(plan)})
        return self._plan_index[1].get(self._key(task))

    # -- the contract
    def submit(self, task: AnalyticsTask, now_ms: float) -> list[Decision]:
        """A task that arrives as predicted (same drone and model, frame within ``same_frame_ms`` of the predicted
        time) takes the predicted task's place in the cached plan, which stays optimal: same release, deadline and
        gain. Any other arrival makes the policy re-plan."""
        self.arrivals.observe(task)
        times = self._predicted.get((task.drone, task.model), ())
        match = [f for f in times if abs(f - task.arrival_ms) < self.arrivals.same_frame_ms]
        if match:
            task.notes["plan_key"] = (task.drone, task.model, match[0])
            self.counters["arrived_as_predicted"] += 1
        else:
            self._version += 1
        return super().submit(task, now_ms)

    def _lose(self, task: AnalyticsTask, now_ms: float, why: str) -> Decision:
        self._version += 1
        return super()._lose(task, now_ms, why)

    def _sweep(self, now_ms: float) -> list[Decision]:
        start = self._edge_free_at(now_ms)
        out = []
        for t in list(self.pool):
            end, proc, _ = self._variants(t.model, t.deadline_ms, 0.0)[0]
            if t.notes.get("mode") != OPEN and start + proc > end:
                out.append(self._lose(t, now_ms, f"edge time {proc:.0f} ms no longer fits (at the "
                                                 f"{100 * self._tails[0][1]:.0f} % level)"))
        return out

    def poll(self, now_ms: float) -> list[Decision]:
        self._now = now_ms
        if self._wake is not None and self._wake <= now_ms:
            self._wake = None
        out = self._sweep(now_ms)
        due = sorted((t for t in self.pool if t.notes.get("mode") == OPEN and self.trigger_ms(t) - now_ms <= self.jit_early_ms),
                     key=self.trigger_ms)
        for t in due:  # committing a planned task or releasing an unplanned one keeps the plan optimal
            if self._cloud_option_gone(t, now_ms):
                t.notes["mode"] = EDGE_ONLY  # an edge candidate until it no longer fits
                self.counters["cloud_option_lost"] += 1
                self._version += 1
            elif self._planned_start(t, now_ms) is not None:
                t.notes["mode"] = COMMITTED
                self.counters["committed_to_edge"] += 1
            else:
                out.append(self._release_to_cloud(t, now_ms, "at its cloud trigger: not in the edge plan"))
        return out

    def next_poll_ms(self) -> float | None:
        nxt = super().next_poll_ms()
        if self._wake is not None:
            nxt = self._wake if nxt is None else min(nxt, self._wake)
        return nxt

    def _pop_edge(self, now_ms: float) -> tuple[AnalyticsTask | None, list[Decision]]:
        self._now = now_ms
        drops = self._sweep(now_ms)
        plan = self.schedule(now_ms)
        self._wake = None
        if not plan:
            return None, drops
        first = next((t for t in self.pool if self._key(t) == plan[0][0]), None)
        if first is None:
            # wait for a predicted arrival; re-plan then (at least 1 ms on: a poll never repeats at the same time)
            self._wake = max(self._first_wake, now_ms + 1.0) if self._first_wake is not None else now_ms + 1.0
            self.counters["edge_waits_for_prediction"] += 1
            return None, drops
        self.pool.remove(first)
        self._version += 1
        # the rest of an optimal plan is optimal for the rest (principle of optimality): keep it while the edge
        # runs the first task, until that task is due to end. Started ``lag`` ms after its planned start (within the
        # plan's tolerance), the rest moves as much later and has as much less slack
        lag, slack = max(0.0, now_ms - plan[0][1]), self._cache.slack  # schedule() above set the cache
        rest = [(k, s + lag) for k, s in plan[1:]] if lag > 0 else plan[1:]
        self._cache = _CachedPlan((self._version, False), rest, None,
                                  now_ms + self.w[first.model].edge_ms + self._tolerance(slack - lag), slack - lag)
        if first.notes.get("mode") == OPEN:
            self.counters["open_started_on_edge"] += 1
        return first, drops

    def on_edge_done(self, task: AnalyticsTask, now_ms: float, exec_ms: float) -> list[Decision]:
        out = super().on_edge_done(task, now_ms, exec_ms)
        if exec_ms > 0:
            self._edge_obs.append(exec_ms / self.w[task.model].edge_ms)
            xs = sorted(self._edge_obs)
            self._edge_mean = max(1e-3, sum(xs) / len(xs))
            if len(xs) >= 10:
                self._tails = [(max(0.0, xs[min(len(xs) - 1, max(0, math.ceil(q * len(xs)) - 1))] - self._edge_mean), q)
                               for q in self.edge_levels]
        self._vparts.clear()
        self._version += 1
        return out

    def on_cloud_availability(self, available: bool, now_ms: float) -> list[Decision]:
        self._version += 1
        return super().on_cloud_availability(available, now_ms)
