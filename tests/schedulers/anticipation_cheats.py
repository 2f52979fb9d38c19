"""CHEATING policies (test fixtures, never production code) that the non-anticipation test must catch.

Each is DEM (:class:`aerodaas.schedulers.analytics_dems.Dem`) plus one way of learning what a real dispatcher only
reveals later. Two are handed the future (the test's ``peek`` hook, in the harness's process): they test that the
cut comparison flags a policy that uses it. Three attack the harness the ways it was once fooled
(a small public seed, the policy in the harness's process, one process for many runs):

* :class:`RecomputeDraw` walks the call stack to the harness and recomputes the cloud draw from its seed;
* :class:`InferSeed` searches the public seeding scheme for the seed that gives the first revealed latency, then
  recomputes every later draw from it;
* :class:`CrossRunCache` remembers every revealed latency across the runs of its process and uses a remembered one
  instead of the profile.

Each keeps a counter of how often its trick worked (``cheat_hits``) for the test's diagnostics; the test judges
them by their decisions only.
"""
from __future__ import annotations

import sys

from aerodaas.schedulers.analytics_base import AnalyticsTask, Decision, EXECUTED_STATES
from aerodaas.schedulers.analytics_dems import Dem
from aerodaas.schedulers.dispatch.emulation import Jitter, seeded_rng

#: the configuration the attacks assume public (the test's: lognormal cloud jitter 0.2, one edge "edge00")
CLOUD_JITTER = Jitter("lognormal", 0.2)
EDGE_ID = "edge00"


class PeekArrivals(Dem):
    """DEM that reads the trace ahead — a task whose frame is followed by another drone's frame within
    ``lookahead_ms`` goes straight to the cloud, as if it knew the edge would be contended. 400 ms is about the
    median gap to another drone's next frame in the test's 3-drone HEAVY traces (10th-90th percentile 110-560 ms),
    so the peek decides unlike DEM as often as it can: a shorter or longer look ahead is the same in more futures."""

    name = "CHEAT_PEEK_ARRIVALS"
    lookahead_ms = 400.0

    def peek(self, trace, harness) -> None:
        self._arrivals = sorted((t.arrival_ms, t.drone) for t in trace)

    def submit(self, task: AnalyticsTask, now_ms: float) -> list[Decision]:
        if any(now_ms < a <= now_ms + self.lookahead_ms and d != task.drone for a, d in self._arrivals):
            self.counters["cheat_hits"] += 1
            return [self._cloud_or_drop(task, now_ms, "peeked: contention ahead")]
        return super().submit(task, now_ms)


class PeekDraws(Dem):
    """DEM whose cloud re-check reads the task's true cloud round trip (the harness's draw) instead of the
    profile — the draw a real dispatcher only learns when the reply comes back."""

    name = "CHEAT_PEEK_DRAWS"

    def peek(self, trace, harness) -> None:
        self._draw = harness.cloud_round_trip_ms

    def cloud_admit(self, task: AnalyticsTask, now_ms: float) -> bool:
        self.counters["cheat_hits"] += 1
        return now_ms + self._draw(task, now_ms) <= task.deadline_ms


class _KnowsDraws(Dem):
    """DEM whose cloud re-check uses :meth:`_known_ms` (a cloud round trip it claims to know) when it has one."""

    def _known_ms(self, task: AnalyticsTask) -> float | None:
        raise NotImplementedError

    def cloud_admit(self, task: AnalyticsTask, now_ms: float) -> bool:
        known = self._known_ms(task)
        if known is None:
            return super().cloud_admit(task, now_ms)
        self.counters["cheat_hits"] += 1
        return now_ms + known <= task.deadline_ms


def _draw(seed, task: AnalyticsTask, profile_ms: float) -> float:
    """The harness's cloud draw of ``task`` with ``seed`` (no network model): the public seeding scheme."""
    return profile_ms * CLOUD_JITTER.factor(seeded_rng(seed, "cloud", EDGE_ID, task.task_id))


class RecomputeDraw(_KnowsDraws):
    """Walks up the call stack to a frame whose ``self`` has ``seed``, ``edge_id`` and ``cloud_round_trip_ms`` (the
    harness) and recomputes the task's cloud draw from that seed — it never calls the harness, so a harness that
    re-draws after a cut does not see it."""

    name = "CHEAT_RECOMPUTE_DRAW"

    def _known_ms(self, task: AnalyticsTask) -> float | None:
        f = sys._getframe(1)
        while f is not None:
            h = f.f_locals.get("self")
            if h is not None and all(hasattr(h, a) for a in ("seed", "edge_id", "cloud_round_trip_ms")):
                return self.w[task.model].cloud_ms * CLOUD_JITTER.factor(
                    seeded_rng(h.seed, "cloud", h.edge_id, task.task_id))
            f = f.f_back
        return None


class InferSeed(_KnowsDraws):
    """Learns the seed from the first cloud latency revealed: tries seeds 0 .. ``search - 1`` of the public scheme
    and keeps the one that reproduces it (to 1 µs); from then on it knows every cloud draw."""

    name = "CHEAT_INFER_SEED"
    search = 500

    def __init__(self, workload, **kw) -> None:
        super().__init__(workload, **kw)
        self._seed: int | None = None
        self._tried = False

    def on_cloud_done(self, task: AnalyticsTask, now_ms: float, latency_ms: float) -> list[Decision]:
        if not self._tried and task.state in EXECUTED_STATES and task.start_ms is not None:
            self._tried = True
            prof = self.w[task.model].cloud_ms
            self._seed = next((s for s in range(self.search) if abs(_draw(s, task, prof) - latency_ms) < 1e-3), None)
        return super().on_cloud_done(task, now_ms, latency_ms)

    def _known_ms(self, task: AnalyticsTask) -> float | None:
        return None if self._seed is None else _draw(self._seed, task, self.w[task.model].cloud_ms)


class CrossRunCache(_KnowsDraws):
    """Remembers the first cloud latency it is told for each task id, across the runs of its process (a class
    attribute), and uses a remembered latency instead of the profile: after one warm-up run on the same seed it
    knows every draw."""

    name = "CHEAT_CROSS_RUN_CACHE"
    seen: dict[int, float] = {}

    def on_cloud_done(self, task: AnalyticsTask, now_ms: float, latency_ms: float) -> list[Decision]:
        if task.state in EXECUTED_STATES:
            self.seen.setdefault(task.task_id, latency_ms)
        return super().on_cloud_done(task, now_ms, latency_ms)

    def _known_ms(self, task: AnalyticsTask) -> float | None:
        return self.seen.get(task.task_id)


class Raises(Dem):
    """Not a cheat: a policy that fails on its first arrival (the isolated process must report its traceback)."""

    name = "TEST_RAISES"

    def submit(self, task: AnalyticsTask, now_ms: float) -> list[Decision]:
        return [1 / 0]
