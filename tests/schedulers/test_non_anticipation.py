"""Non-anticipation of every analytics-scheduler policy, by construction, with five cheating policies it must catch.

A policy is non-anticipative when its decisions before any time T depend only on what was revealed before T: the
arrivals before T, and the edge and cloud execution times of the tasks that *completed* before T. The test runs each
policy on runs that agree on everything revealed before T and differ in everything revealed at or after it: the
arrivals at or after T (another trace), and every edge or cloud draw that completes at or after T (re-drawn from
another seed, kept at or after T so it is still unrevealed before T). The decision logs and edge starts before T
must be identical.

By construction (:mod:`aerodaas.bench.isolation`): every trace and every draw comes from a 256-bit secret
(:func:`secret_seed`), recorded in the check's result only after the runs; the post-cut run replays the past
exactly (the same secret for draws that complete before T) and re-draws the rest from a fresh secret; the policy
runs in a fresh process for every run (:class:`IsolatedPolicy`), built from its name alone, holding no harness, no
trace and no seed; and a warm-up run with its own secrets comes first, so a cache kept across runs holds another
run's future.

Cuts: uniform ones, plus cuts just before arrivals (1 ms and 1 µs before), so that a policy reading arrivals even a
few hundred ms ahead is caught; cloud and edge times are jittered (lognormal σ 0.2 / 0.05), so a policy reading a
draw before the task completes is caught.

The five cheats (``tests/schedulers/anticipation_cheats.py``): ``PeekArrivals`` and ``PeekDraws`` are handed the future
(trace, draws) and must be *flagged* by the cut comparison (at >= 2 cuts). ``RecomputeDraw`` (walks the stack to
the harness's seed), ``InferSeed`` (searches the public seeding scheme) and ``CrossRunCache`` (latencies kept across
runs of a process) must *reach nothing*: isolated, with secret seeds, their decisions are exactly honest DEM's on
the same secret draws; and the test shows that each of the three fooled the old protocol (public seeds, the
policy in the harness's process, one process for every run): 0 cuts flagged while its decisions were not DEM's.
No policy can be flagged for anticipation it cannot commit: for these three, "caught" is "its trick is shown to
work without the protections and to change nothing with them".
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

import pytest

from aerodaas.bench.harness import Harness, Result, make_trace
from aerodaas.bench.isolation import IsolatedPolicy, secret_seed
from aerodaas.bench.traces import TraceSpec
from aerodaas.schedulers.analytics_base import AnalyticsTask, Workload
from aerodaas.schedulers.dispatch.emulation import Jitter, seeded_rng

from tests.schedulers import anticipation_cheats as cheats
from tests.conftest import DATA_DIR, needs_workload

WORKLOAD_JSON = DATA_DIR / "workloads" / "ocularone_lambda.json"

REAL = ["EDGE_FIFO", "EDGE_EDF", "EDGE_SJF", "EDGE_HBF", "EDGE_HUF", "CLOUD", "E+C", "DEM", "DEMS", "DEMS-A", "GEMS",
        "GAINPLAN", "EVPLAN", "LAPLAN"]
#: the old protocol's public seeds (trace, draws, re-draws, other trace), kept to show what it let through
PUBLIC = (21, 7, 1007, 99)
DURATION_S = 12.0


def _ref(cls) -> str:
    return f"{cls.__module__}:{cls.__qualname__}"


# ------------------------------------------------------------------------------------------------ the cut runs
class CutHarness(Harness):
    """The policy harness with every edge and cloud draw that completes at or after ``cut`` re-drawn from
    ``alt_seed`` (and held at or after ``cut``, so it stays unrevealed before it). ``cut`` None: the plain draws."""

    def __init__(self, policy, *, cut: float | None, alt_seed, **kw) -> None:
        super().__init__(policy, **kw)
        self.cut, self.alt_seed = cut, alt_seed

    def _alt(self, base: float, start: float, profile_ms: float, jitter: Jitter, kind: str, task) -> float:
        if self.cut is None or start + base < self.cut:
            return base
        alt = max(profile_ms * jitter.factor(seeded_rng(self.alt_seed, kind, self.edge_id, task.task_id)),
                  self.cut - start)
        while start + alt < self.cut:  # start + (cut - start) can round below the cut: it would be revealed before it
            alt = math.nextafter(alt, math.inf)
        return alt

    def edge_hold_ms(self, task):
        return self._alt(super().edge_hold_ms(task), self.now, self.w[task.model].edge_ms, self.edge_jitter, "edge",
                         task)

    def cloud_round_trip_ms(self, task, send_ms):
        return self._alt(super().cloud_round_trip_ms(task, send_ms), send_ms, self.w[task.model].cloud_ms,
                         self.cloud_jitter, "cloud", task)


def _copy(tasks):
    return [AnalyticsTask(t.task_id, t.drone, t.model, t.arrival_ms, t.deadline_ms) for t in tasks]


def _run(policy, w, trace, cut, seed, alt_seed, until_ms: float | None = None, options: dict | None = None) -> Result:
    """One run. ``policy``: a registered name or ``"module:Class"`` (isolated: a fresh process, built with
    ``options``) or a class (in the harness's process, handed the trace and the harness if it has ``peek``).
    ``until_ms``: the run stops there (:meth:`Harness.run`; a post-cut run is compared only before its cut, so
    what a policy does on the other future after the cut is not run: the reference run covers the whole trace)."""
    pol = IsolatedPolicy(policy, w, options) if isinstance(policy, str) else policy(w)
    # admit_probes False: the cloud re-check asked once, at the send time (what decides the send), not bisected
    # into an admit-by time: a pipe round trip per call to an isolated policy
    h = CutHarness(pol, cut=cut, alt_seed=alt_seed, edge_jitter=Jitter("lognormal", 0.05),
                   cloud_jitter=Jitter("lognormal", 0.2), seed=seed, admit_probes=False)
    trace = _copy(trace)
    if hasattr(pol, "peek"):
        pol.peek(trace, h)
    try:
        return h.run(trace, until_ms=until_ms)
    finally:
        if isinstance(pol, IsolatedPolicy):
            pol.close()


def _before(res, cut):
    return ([e for e in res.log if e[0] < cut], [(t.task_id, s) for t, s in res.edge_starts if s < cut])


def cuts(trace, n_uniform: int = 6, n_arrivals: int = 8, seed: int = 3, start_ms: float = 1000.0) -> list[float]:
    """Cut points: ``n_uniform`` uniform in the trace's span, and 1 ms and 1 µs before ``n_arrivals`` arrivals
    picked at random; every one after ``start_ms`` (the first second, where little has happened yet) and after the
    trace's first arrival (before it nothing can be decided, and a random trace's first frame can come after 1 s)."""
    rng = random.Random(seed)
    span = trace[-1].arrival_ms
    lo = max(start_ms, min(t.arrival_ms for t in trace))
    arr = sorted({t.arrival_ms for t in trace if t.arrival_ms - 1.0 > lo})
    picks = rng.sample(arr, min(n_arrivals, len(arr)))
    return sorted([rng.uniform(lo, span) for _ in range(n_uniform)] + [a - 1.0 for a in picks]
                  + [a - 0.001 for a in picks])


#: a drone's frame gap shorter than this (ms; the 1 fps traces' mean gap) is a burst, longer than SILENCE_MS a silence
BURST_MS, SILENCE_MS = 1000.0, 2000.0


def shape_cuts(trace, n: int = 2, seed: int = 5, start_ms: float = 1000.0) -> dict[str, list[float]]:
    """Cuts inside the bursts and silences of ``trace``: the midpoints of ``n`` of its drones' frame gaps shorter
    than :data:`BURST_MS` (``"burst"``) and of ``n`` longer than :data:`SILENCE_MS` (``"silence"``), picked at
    random after ``start_ms`` (a drone's gaps: between its consecutive frames)."""
    frames: dict[str, list[float]] = {}
    for t in trace:
        if not frames.setdefault(t.drone, []) or frames[t.drone][-1] != t.arrival_ms:
            frames[t.drone].append(t.arrival_ms)
    gaps = [(a, b) for ts in frames.values() for a, b in zip(ts, ts[1:]) if (a + b) / 2 > start_ms]
    rng = random.Random(seed)
    out = {}
    for name, keep in (("burst", lambda g: g < BURST_MS), ("silence", lambda g: g > SILENCE_MS)):
        mids = sorted((a + b) / 2 for a, b in gaps if keep(b - a))
        out[name] = sorted(rng.sample(mids, min(n, len(mids))))
    return out


@dataclass
class Check:
    """The outcome of :func:`check`: the cuts, those flagged, the reference run and the seeds it used (recorded
    after the runs; bytes for secrets)."""

    cuts: list[float]
    flagged: list[float]
    reference: Result
    trace: list
    seeds: dict = field(default_factory=dict)
    #: bursty kinds: the cuts inside the trace's bursts and silences (see :func:`shape_cuts`), also in ``cuts``
    shape: dict = field(default_factory=dict)


def _trace_seed(secret: bool, public: int) -> int:
    return int.from_bytes(secret_seed(), "little") if secret else public


def cut_trace(w, seed: int, kind: str | None = None, *, drones: int = 3, duration_s: float = DURATION_S) -> list:
    """The cut comparison's single-edge trace. ``kind`` None: :func:`aerodaas.bench.harness.make_trace` (1 fps,
    250 ms jitter; the policy tests' trace). Else a trace kind of :class:`TraceSpec` with its default parameters
    (``"onoff"``, ``"pareto"``, ``"flush"``: the bursty kinds), made as the runtime benchmark and the
    sweep make it (:func:`aerodaas.bench.workload.make_trace`, one edge of ``drones`` drones at 1 fps), its tasks
    numbered from 0 in arrival order as the harness's trace."""
    if kind is None:
        return make_trace(w, drones=drones, duration_s=duration_s, seed=seed, jitter_ms=250.0)
    from aerodaas.bench.workload import make_trace as fleet_trace

    rows = fleet_trace(w, drones, duration_s, seed, drones_per_edge=drones, trace=TraceSpec.parse(kind))
    return [AnalyticsTask(n, d, m, t, t + w[m].deadline_ms) for n, (t, _, d, m) in enumerate(rows)]


def check(policy, w, *, secret: bool = True, warm_up: bool = True, every: int = 1, n_arrivals: int = 8,
          kind: str | None = None, drones: int = 3, duration_s: float = DURATION_S,
          options: dict | None = None) -> Check:
    """Run ``policy`` (see :func:`_run`) through the cut comparison. ``secret`` False: the old protocol's public
    seeds (:data:`PUBLIC`), the same re-draw seed at every cut. ``warm_up``: one run before the reference run (its
    own secrets, or, publicly, the reference run's own seeds: what a cross-run cache needs to pass). ``every``: use
    every n-th cut only. ``n_arrivals``: how many arrivals get a cut just before them (see :func:`cuts`).
    ``kind``, ``drones``, ``duration_s``: the traces (see :func:`cut_trace`; the post-cut future is another trace of
    the same kind). ``options``: the isolated policy's (its constructor's keywords). A bursty kind's cuts begin
    1 s after its first frame (the first seconds can be silent: nothing decided before a cut there), its trace is
    re-drawn (another secret) until it has a burst and a silence after that, and it gets cuts inside both
    (:func:`shape_cuts`)."""
    trace_seed, seed = _trace_seed(secret, PUBLIC[0]), (secret_seed() if secret else PUBLIC[1])
    a = cut_trace(w, trace_seed, kind, drones=drones, duration_s=duration_s)
    shape = {}
    if kind is not None:
        for _ in range(100):
            shape = shape_cuts(a, start_ms=a[0].arrival_ms + 1000.0)
            if shape["burst"] and shape["silence"]:
                break
            trace_seed = _trace_seed(secret, trace_seed + 1)
            a = cut_trace(w, trace_seed, kind, drones=drones, duration_s=duration_s)
        assert shape["burst"] and shape["silence"], f"no {kind} trace with a burst and a silence: {shape}"
    if warm_up:
        wt = a if not secret else cut_trace(w, _trace_seed(True, 0), kind, drones=drones, duration_s=duration_s)
        _run(policy, w, wt, None, secret_seed() if secret else seed, None, options=options)
    ra = _run(policy, w, a, None, seed, None, options=options)
    flagged = []
    start_ms = 1000.0 if kind is None else a[0].arrival_ms + 1000.0
    points = sorted(cuts(a, n_arrivals=n_arrivals, start_ms=start_ms)[::every] + shape.get("burst", [])
                    + shape.get("silence", []))
    for cut in points:
        other = cut_trace(w, _trace_seed(secret, PUBLIC[3]), kind, drones=drones, duration_s=duration_s)
        prefix = [t for t in a if t.arrival_ms < cut]
        b = prefix + [AnalyticsTask(len(prefix) + i, t.drone, t.model, t.arrival_ms, t.deadline_ms)
                      for i, t in enumerate(t for t in other if t.arrival_ms >= cut)]
        assert [(t.drone, t.model, t.arrival_ms) for t in a[len(prefix):]] != \
            [(t.drone, t.model, t.arrival_ms) for t in b[len(prefix):]]      # the futures really differ
        rb = _run(policy, w, b, cut, seed, secret_seed() if secret else PUBLIC[2], until_ms=cut, options=options)
        before_a = _before(ra, cut)
        # not a vacuous comparison: a decision logged or an edge start before the cut (an edge-only policy logs a
        # task when it ends, and with a secret trace seed the first end can come after an early cut)
        assert before_a[0] or before_a[1], (
            f"nothing decided before the cut {cut}: first arrivals {[round(t.arrival_ms, 1) for t in a[:4]]}, "
            f"{len(ra.log)} decisions in all (first {ra.log[:2]}), edge starts {ra.edge_starts[:2]}, "
            f"task states {dict(ra.states)}")
        if before_a != _before(rb, cut):
            flagged.append(cut)
    return Check(points, flagged, ra, a, {"trace": trace_seed, "draws": seed}, shape)


def _heavy() -> Workload:
    return Workload.from_file(WORKLOAD_JSON, "HEAVY")


@needs_workload
def test_every_cut_comes_after_the_traces_first_arrival():
    """A trace whose first frame comes after the first second (one in about 500 secret traces): no cut lands before
    that frame, where the reference run cannot have decided anything, even with every arrival picked."""
    a = cut_trace(_heavy(), PUBLIC[0])
    late = [AnalyticsTask(t.task_id, t.drone, t.model, t.arrival_ms + 1500.0, t.deadline_ms + 1500.0) for t in a]
    first = late[0].arrival_ms
    assert first > 1000.0
    points = cuts(late, n_arrivals=len(late))
    assert len(points) > 6 and min(points) > first, (first, points[:4])


@needs_workload
@pytest.mark.parametrize("name", REAL)
def test_policy_is_non_anticipative(name):
    res = check(name, _heavy())
    assert res.flagged == [], f"{name} anticipates at cuts {res.flagged} (seeds, recorded after the run: {res.seeds})"


@needs_workload
@pytest.mark.parametrize("cheat", [cheats.PeekArrivals, cheats.PeekDraws])
def test_cheats_handed_the_future_are_flagged(cheat):
    """A policy handed the future (in the harness's process) is flagged at several cuts: the comparison sees it.
    16 arrival cuts (32 of the 38 cuts): whether a peek changes a decision before a cut depends on the secret
    trace; with the 8 of the policy test, PeekArrivals was flagged at fewer than 2 cuts in 3 of 400 checks, with 16
    in 0 of 400 (each flagged at 2 or more; at 3 or more in 398)."""
    res = check(cheat, _heavy(), n_arrivals=16)
    assert len(res.flagged) >= 2, res.flagged


@needs_workload
@pytest.mark.parametrize("cheat", [cheats.RecomputeDraw, cheats.InferSeed, cheats.CrossRunCache])
def test_attacks_on_the_harness_reach_nothing(cheat):
    """In a fresh process with a secret seed the attack finds no harness, no seed and no earlier run: the cheat's
    decisions are exactly DEM's on the same secret trace and draws (its trick changed nothing), and no cut flags
    it (a warm-up run first, as a cache needs)."""
    w = _heavy()
    res = check(_ref(cheat), w, every=4)
    assert res.flagged == []
    dem = _run("DEM", w, res.trace, None, res.seeds["draws"], None)
    assert res.reference.log == dem.log
    assert [(t.task_id, s) for t, s in res.reference.edge_starts] == [(t.task_id, s) for t, s in dem.edge_starts]


@needs_workload
@pytest.mark.parametrize("cheat", [cheats.RecomputeDraw, cheats.InferSeed, cheats.CrossRunCache])
def test_the_old_protocol_was_fooled(cheat):
    """Why the protections: with the old protocol (public seeds, the policy in the harness's process, the same
    process for every run) each of the three attacks changes decisions (it is not DEM) and yet no cut flags it."""
    w = _heavy()
    cheats.CrossRunCache.seen.clear()
    try:
        res = check(cheat, w, secret=False)
    finally:
        cheats.CrossRunCache.seen.clear()
    dem = _run(cheats.Dem, w, res.trace, None, PUBLIC[1], None)
    assert res.flagged == []
    assert res.reference.log != dem.log


@needs_workload
@pytest.mark.parametrize("name", ["DEMS-A", "LAPLAN"])
def test_an_isolated_policy_decides_as_in_process(name):
    """The process boundary changes no decision: the same policy on the same secret trace and draws, isolated and
    in the harness's process, gives the same decision log and edge starts."""
    from aerodaas.schedulers.analytics_base import analytics_scheduler_class

    w = _heavy()
    trace = make_trace(w, drones=3, duration_s=DURATION_S, seed=_trace_seed(True, 0), jitter_ms=250.0)
    seed = secret_seed()
    iso, local = _run(name, w, trace, None, seed, None), _run(analytics_scheduler_class(name), w, trace, None, seed, None)
    assert iso.log == local.log
    assert [(t.task_id, s) for t, s in iso.edge_starts] == [(t.task_id, s) for t, s in local.edge_starts]
    assert iso.utility == local.utility


@needs_workload
def test_cheats_are_caught_only_by_what_changes_after_the_cut():
    """Sanity of the method: with the same future (the same trace, the draws after the cut "re-drawn" from the same
    seed), no cheat handed the future is flagged at any cut — a cheat is caught for what it read from the future,
    not for noise of the cut machinery."""
    w = _heavy()
    a = make_trace(w, drones=3, duration_s=DURATION_S, seed=_trace_seed(True, 0), jitter_ms=250.0)
    seed = secret_seed()
    for cheat in (cheats.PeekArrivals, cheats.PeekDraws):
        for cut in cuts(a)[::3]:
            assert _before(_run(cheat, w, a, None, seed, None), cut) == _before(_run(cheat, w, a, cut, seed, seed), cut)


@needs_workload
def test_an_isolated_policy_that_raises_is_reported_with_its_traceback():
    from aerodaas.bench.isolation import PolicyProcessError

    w = _heavy()
    trace = make_trace(w, drones=1, duration_s=2.0, seed=1, jitter_ms=0.0)
    with pytest.raises(PolicyProcessError, match="ZeroDivisionError"):
        _run(_ref(cheats.Raises), w, trace, None, secret_seed(), None)
    with pytest.raises(PolicyProcessError, match="NO_SUCH_POLICY"):
        IsolatedPolicy("NO_SUCH_POLICY", w)
