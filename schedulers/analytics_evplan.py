"""EVPLAN: GAINPLAN's max-gain edge plan, with the cloud option valued by its *expected* utility under the observed
latency distribution, and an edge plan that leaves room for the observed edge-time spread.

Why. GAINPLAN (and DEMS) treat the cloud as deterministic: a task "fits" the cloud if ``now + estimate <=
deadline``, and a just-in-time release leaves 10-60 ms of margin. With cloud round trips that vary (the
benchmark's lognormal jitter, a latency step) two things go wrong, both measured with the policy harness
(``aerodaas bench schedulers --harness``, HEAVY, 3 drones per edge, σ = 0.1): a point estimate either sends tasks
that come back late (cost paid, no benefit; DEMS-A) or — a pessimistic one — gives up the cloud option of the long
models whose deadline leaves little slack (DEO: 950 ms deadline, 832 ms cloud time), although sent at once they are
on time 9 times in 10 and worth +15 each (GAINPLAN with a p95 estimate drops 912 DEO of 1,440). And plans packed to
the profile's edge times end late on the edge when the edge time varies by a few percent (19 % of GAINPLAN's DEO
edge runs at 5 % edge jitter).

Rules (all times ms; ``c`` = the model's profile cloud time, ``b`` benefit, ``cc`` cloud cost):

* Latency model: per model, the ratios ``observed round trip / c`` of the last ``window`` (100) cloud completions
  (the pooled ratios of every model while a model has fewer than 5; the profile, ratio 1, before any). ``P(s)`` =
  the fraction of those ratios with ``ratio * c <= s``: the chance a task sent with ``s`` ms left is on time.
* Expected cloud value of a task at time t: ``V(t) = P(deadline - t) * b - cc``. A task is *open* (keeps a cloud
  option) while ``V > 0``; otherwise it is an edge-only candidate, dropped when it no longer fits on the edge.
* Edge plan: GAINPLAN's exact max-gain plan (Lawler & Moore), with gain ``edge utility - max(0, V(now))`` for an
  open task, and each model's edge time scaled by the 95th percentile of the observed ``edge run / profile``
  ratios (1 before any): a plan that fits at that time finishes in time ~95 % of the time per task.
* Release: an open task is held while waiting costs almost no cloud probability: until ``deadline - c *
  Q(P0 - 0.02) - 10`` (``P0`` = its on-time chance at arrival, ``Q`` the ratio quantile), acted on 50 ms early as
  DEMS's JIT queue. With exact timing that is DEMS's cloud trigger; with jitter it is earlier, and for a task
  whose cloud option starts decaying at once (DEO above) it is its arrival. At the trigger it is committed to the
  edge if the plan starts it soon (GAINPLAN's rule), else sent to the cloud if ``V > 0``, else kept as an edge-only
  candidate. The cloud re-check admits it while ``V`` stays positive.

With ``estimator=SPEC`` (the fair-margin option) the ratio window is replaced by that point estimate (``P`` is 1
if the estimate fits, else 0), which is GAINPLAN's rule with that estimator plus the edge-time spread.
"""
from __future__ import annotations

import math
from collections import deque

from aerodaas.schedulers.analytics_base import EXECUTED_STATES, AnalyticsTask, Decision, Workload
from aerodaas.schedulers.analytics_dems import CLOUD_TRIGGER_BUFFER_MS
from aerodaas.schedulers.analytics_estimators import make_estimator
from aerodaas.schedulers.analytics_gainplan import EDGE_ONLY, OPEN, GainPlan, max_gain_edge_plan

__all__ = ["EvPlan"]


class EvPlan(GainPlan):
    """EVPLAN (see the module docstring). Options: ``window`` (cloud ratios kept per model, default 100),
    ``tolerance`` (cloud on-time probability a hold may cost, default 0.02), ``edge_quantile`` (of the edge-time
    ratios the plan uses, default 0.95), ``estimator`` (point-estimate mode), ``commit_horizon_ms`` (as GAINPLAN).
    Raises ValueError for out-of-range options."""

    name = "EVPLAN"
    options = ("estimator", "commit_horizon_ms", "window", "tolerance", "edge_quantile")

    def __init__(self, workload: Workload, *, window: int = 100, tolerance: float = 0.02, edge_quantile: float = 0.95,
                 estimator: str | None = None, commit_horizon_ms: float | None = None) -> None:
        super().__init__(workload, commit_horizon_ms=commit_horizon_ms)
        if window < 1:
            raise ValueError(f"window must be >= 1, got {window}")
        if not 0 <= tolerance < 1:
            raise ValueError(f"tolerance must be in [0, 1), got {tolerance}")
        if not 0 < edge_quantile <= 1:
            raise ValueError(f"edge_quantile must be in (0, 1], got {edge_quantile}")
        self.tolerance, self.edge_quantile = float(tolerance), float(edge_quantile)
        self.point = make_estimator(estimator, workload) if estimator else None
        self.ratios = {m: deque(maxlen=window) for m in workload.models}
        #: this many consecutive ratios outside the older ones' 5-95 % range restart the model's window
        self.shift_n = 4
        self.pooled: deque[float] = deque(maxlen=5 * window)
        self.edge_ratios: deque[float] = deque(maxlen=100)
        self._edge_scale = 1.0
        self._sorted: dict[str, list[float]] = {}

    # -- the latency model
    def _ratios(self, model: str) -> list[float]:
        if model not in self._sorted:
            own = self.ratios[model]
            src = own if len(own) >= 5 else (self.pooled or own)
            self._sorted[model] = sorted(src) if src else [1.0]
        return self._sorted[model]

    def on_time_chance(self, model: str, slack_ms: float) -> float:
        """P(a round trip of ``model`` takes <= ``slack_ms``) under the observed ratios (or the point estimate)."""
        c = self.w[model].cloud_ms
        if self.point is not None:
            return 1.0 if self.point.value(model) <= slack_ms else 0.0
        xs = self._ratios(model)
        lo, hi = 0, len(xs)
        while lo < hi:  # count of ratios r with r * c <= slack
            mid = (lo + hi) // 2
            if xs[mid] * c <= slack_ms:
                lo = mid + 1
            else:
                hi = mid
        return lo / len(xs)

    def ratio_quantile(self, model: str, p: float) -> float:
        """The smallest observed ratio r with P(ratio <= r) >= p (the point estimate / c in point mode)."""
        if self.point is not None:
            return self.point.value(model) / self.w[model].cloud_ms
        xs = self._ratios(model)
        return xs[min(len(xs) - 1, max(0, math.ceil(p * len(xs)) - 1))]

    def cloud_value(self, task: AnalyticsTask, at_ms: float) -> float:
        """Expected utility of sending ``task`` to the cloud at ``at_ms``: P(on time) * benefit - cloud cost."""
        p = self.w[task.model]
        return self.on_time_chance(task.model, task.deadline_ms - at_ms) * p.benefit - p.cloud_cost

    def cloud_estimate_ms(self, model: str) -> float:
        return self.w[model].cloud_ms * self.ratio_quantile(model, 0.5)

    # -- GAINPLAN's hooks
    def gain(self, task: AnalyticsTask) -> float:
        p = self.w[task.model]
        if task.notes.get("mode") == OPEN:
            return p.edge_utility - max(0.0, self.cloud_value(task, self._now))
        return p.edge_utility

    def _plan(self, start_ms: float) -> list[AnalyticsTask]:
        k = self._edge_scale
        cands = [t for t in self.pool if start_ms + k * self.w[t.model].edge_ms <= t.deadline_ms]
        chosen = max_gain_edge_plan([(t.deadline_ms, k * self.w[t.model].edge_ms, self.gain(t)) for t in cands],
                                    start_ms)
        return [cands[i] for i in chosen]

    def _planned_start(self, task: AnalyticsTask, now_ms: float) -> float | None:
        start = self._edge_free_at(now_ms)
        for q in self._plan(start):
            if q is task:
                return start
            start += self._edge_scale * self.w[q.model].edge_ms
        return None

    def trigger_ms(self, task: AnalyticsTask) -> float:
        """Latest hold that costs at most ``tolerance`` of the on-time chance the task had at arrival."""
        r = self.ratio_quantile(task.model, task.notes.get("p0", 1.0) - self.tolerance)
        return task.deadline_ms - self.w[task.model].cloud_ms * r - CLOUD_TRIGGER_BUFFER_MS

    # -- the contract
    def submit(self, task: AnalyticsTask, now_ms: float) -> list[Decision]:
        self._now = now_ms
        p = self.w[task.model]
        self.pool.append(task)
        self._recent.append((now_ms, p.edge_ms))
        if self._first_arrival is None:
            self._first_arrival = now_ms
        if p.cloud_utility > 0 and self.cloud_available and self.cloud_value(task, now_ms) > 0:
            task.notes["mode"] = OPEN
            task.notes["p0"] = self.on_time_chance(task.model, task.deadline_ms - now_ms)
            return self.poll(now_ms) if self.trigger_ms(task) - now_ms <= self.jit_early_ms else []
        task.notes["mode"] = EDGE_ONLY
        if p.edge_utility <= 0 or now_ms + self._edge_scale * p.edge_ms > task.deadline_ms:
            return [self._lose(task, now_ms, "no usable cloud option and no gain from (or time for) the edge")]
        return []

    def _sweep(self, now_ms: float) -> list[Decision]:
        start = self._edge_free_at(now_ms)
        k = self._edge_scale
        return [self._lose(t, now_ms, f"edge time {self.w[t.model].edge_ms:.0f} ms (x{k:.2f}) no longer fits")
                for t in list(self.pool)
                if t.notes.get("mode") != OPEN and start + k * self.w[t.model].edge_ms > t.deadline_ms]

    def _cloud_option_gone(self, task: AnalyticsTask, now_ms: float) -> bool:
        return not self.cloud_available or self.cloud_value(task, now_ms) <= 0

    def _admit_cloud_ms(self, task: AnalyticsTask, now_ms: float) -> float:
        # admitted while the expected value stays positive: slack >= c * Q(cloud cost / benefit)
        p = self.w[task.model]
        return min(p.cloud_ms * self.ratio_quantile(task.model, p.cloud_cost / p.benefit), task.deadline_ms - now_ms)

    def _pop_edge(self, now_ms: float) -> tuple[AnalyticsTask | None, list[Decision]]:
        self._now = now_ms
        return super()._pop_edge(now_ms)

    def on_edge_done(self, task: AnalyticsTask, now_ms: float, exec_ms: float) -> list[Decision]:
        out = super().on_edge_done(task, now_ms, exec_ms)
        if exec_ms > 0:
            self.edge_ratios.append(exec_ms / self.w[task.model].edge_ms)
            xs = sorted(self.edge_ratios)
            self._edge_scale = max(1.0, xs[min(len(xs) - 1, math.ceil(self.edge_quantile * len(xs)) - 1)])
        return out

    def on_cloud_done(self, task: AnalyticsTask, now_ms: float, latency_ms: float) -> list[Decision]:
        if task.state in EXECUTED_STATES:  # only completions are round trips
            r = latency_ms / self.w[task.model].cloud_ms
            own = self.ratios[task.model]
            own.append(r)
            self.pooled.append(r)
            self._sorted.clear()
            if len(own) >= 4 * self.shift_n:  # a shift: the last few leave the older ones' 5-95 % range
                old = sorted(list(own)[:-self.shift_n])
                recent = list(own)[-self.shift_n:]
                lo, hi = old[int(0.05 * len(old))], old[min(len(old) - 1, math.ceil(0.95 * len(old)) - 1)]
                if all(x > hi for x in recent) or all(x < lo for x in recent):
                    self.counters["latency_shift_detected"] += 1
                    own.clear()
                    own.extend(recent)
                    self.pooled.clear()
                    self.pooled.extend(recent)
            if self.point is not None:
                self.point.observe(task.model, latency_ms)
        return []
