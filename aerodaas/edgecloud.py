"""Edge/cloud execution runtime for analytics schedulers: the dispatcher, the executors and the cloud link.

An analytics scheduler (:class:`aerodaas.schedulers.analytics_base.AnalyticsScheduler`) is a pure policy. This
module carries its decisions out on a real Ray cluster, with wall-clock time:

* :class:`AnalyticsDispatcher` -- one per edge device. It owns one policy instance, a monotonic millisecond clock
  (:class:`Clock`), the edge executor loop (one task at a time; asks ``next_edge_task`` whenever the edge is free),
  a timer that calls ``poll`` at ``next_poll_ms``, and cloud submission through a :class:`CloudPool`. It records
  every task's terminal state, tier, times and reason, computes utility with ``task_utility``, and times every
  policy call (decision latency in microseconds). :meth:`AnalyticsDispatcher.submit` is thread-safe, cheap and
  non-blocking, so an edge host's frame path can call it directly.
* Edge executors (:class:`EdgeExecutor`): :class:`EmulatedEdgeExecutor` holds the model's profile time
  (``edge_ms`` x a seeded jitter factor); :class:`OnnxEdgeExecutor` runs a real ONNX detector
  (:func:`aerodaas.detect.make_detector`: YOLOX-Nano, NanoDet-Plus) on the frame.
* :class:`CloudExecutor` -- the cloud side, an asyncio object wrapped as the Ray actor :data:`CloudExecutorActor`
  and placed with ``label_selector={"tier": "cloud"}``. Emulated: it holds ``cloud_ms`` x jitter plus the network
  latency drawn by the :class:`NetworkModel`; real: it decodes the JPEG and runs the ONNX model. Lambda-like: it
  runs any number of tasks at once (real mode: ``threads`` detector threads).
* :class:`CloudPool` -- the edge-side client of the cloud executors, shared by the dispatchers of one process.
* :class:`EdgeHost` (Ray actor :data:`EdgeHostActor`, ``label_selector={"tier": "edge"}``) -- hosts several
  dispatchers (one per emulated edge device) on one asyncio loop; the benchmark replays arrival traces with it.

Threads and clocks
------------------
Everything of one dispatcher runs on one asyncio event loop: the edge loop is a coroutine, the poll timer a
``loop.call_at`` handle, cloud replies arrive as awaited Ray ObjectRefs. Policy calls therefore happen on one
thread, under one lock (the contract of ``analytics_base``). Inside a Ray async actor (``EdgeHost``) the actor's
own loop is used; elsewhere :meth:`AnalyticsDispatcher.start_background` starts a private loop thread.
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

Cloud transport
---------------
One Ray call per cloud task does not scale on a small machine: measured on 2 cores, 400 calls/s to an async actor
gave a p99 completion error of ~200 ms and 800/s collapsed (> 1 s). The pool therefore batches: all requests
created in one loop iteration for one executor go in one ``submit`` call, and each executor keeps one long-poll
``collect`` call per client outstanding, which returns every completion ready at that moment (so the number of
calls adapts to the load, and a completion waits at most one call round trip, a few ms). The executor's death
surfaces on that outstanding call at once (``RayActorError`` / ``ActorDiedError``).

Each Ray hop can be delayed by CPU contention (tens of ms on a busy 2-core machine), while the edge's holds are
timers in one process and stay within a few ms. So in emulated mode the executor holds the task on the intended
schedule (``sent + uplink + cloud time``, absorbing a late request hop), makes the re-check when the request
arrives (before the emulated uplink), and sends the reply ``reply_lead_ms`` (default 100) before it is due; the pool releases it at the due
time, unless the executor died meanwhile (then the task is retried or FAILED as below). The benchmark reports how
early replies arrived (``reply_margin``) and the round trip's error against the intended one.

Cloud node loss
---------------
When a cloud executor dies (its node was removed, the process crashed), the pool records an event (executor,
node id, when, the error, tasks affected). Each task in flight on it is **retried once** on a surviving executor
if there is one and the policy's ``cloud_admit`` still holds at that moment; otherwise it ends FAILED (the cloud
cost is charged, as for any task that ran there) with a reason naming the executor. When no executor is left, every
dispatcher calls ``policy.on_cloud_availability(False, now)`` and carries out what it returns; from then on a
"cloud" decision is dropped (DROPPED_TIME, "cloud unavailable") by the dispatcher as a safety net;
:meth:`CloudPool.add_executor` brings the cloud back (``on_cloud_availability(True)``). Ray reports an actor
on a killed node about 2 s later (measured with Ray 2.60 on a local cluster); tasks sent to it meanwhile are
handled the same way when the loss is seen. A task with no
reply at all ``lost_after_ms`` after its deadline ends FAILED ("no reply"), so no task is ever lost.

Reference for the policies, the workload and the utility model: S. Raj, R. Mittal, H. Gupta, Y. Simmhan,
"Adaptive heuristics for scheduling DNN inferencing on edge and cloud for personalized UAV fleets", FGCS 2025
(arXiv 2412.20860).
"""
from __future__ import annotations

import abc
import asyncio
import concurrent.futures
import hashlib
import itertools
import logging
import math
import os
import random
import re
import sys
import threading
import time
from collections import Counter, defaultdict
from dataclasses import asdict, dataclass, field
from typing import Any, Callable, Iterable, Mapping, Sequence

from aerodaas.schedulers.analytics_base import (
    AnalyticsScheduler, AnalyticsTask, CloudCounters, Decision, TaskState, Workload, admit_by_time, task_utility,
)

__all__ = [
    "Clock", "Jitter", "NetworkModel", "EdgeExecutor", "EmulatedEdgeExecutor", "OnnxEdgeExecutor", "AnalyticsEdgeExecutor",
    "AnalyticsBank", "FramePayload",
    "CloudExecutor", "CloudExecutorActor", "CloudPool", "AnalyticsDispatcher", "EdgeHost", "EdgeHostActor",
    "Samples", "cloud_selector", "start_cloud_executors", "DROP_STATES",
]

log = logging.getLogger(__name__)

DROP_STATES = (TaskState.DROPPED_TIME, TaskState.DROPPED_COST, TaskState.EXPIRED_EDGE)
_DONE_STATES = (TaskState.DONE_ON_TIME, TaskState.DONE_LATE)


# ================================================================================================ clock, randomness
class Clock:
    """Milliseconds since ``t0`` on ``time.monotonic`` (the policies' ``now_ms``).

    ``t0`` (monotonic seconds) defaults to now. :meth:`loop_time` converts a clock time to an asyncio loop time and
    :meth:`epoch` to epoch seconds (``time.time``), for times that cross processes.
    """

    def __init__(self, t0: float | None = None) -> None:
        self.t0 = time.monotonic() if t0 is None else float(t0)

    @classmethod
    def at_epoch(cls, start_epoch: float) -> "Clock":
        """A clock whose 0 ms is the epoch time ``start_epoch`` (s), so several processes share one time origin."""
        return cls(time.monotonic() + (start_epoch - time.time()))

    def now_ms(self) -> float:
        return (time.monotonic() - self.t0) * 1000.0

    def loop_time(self, loop: asyncio.AbstractEventLoop, t_ms: float) -> float:
        return loop.time() + (t_ms - self.now_ms()) / 1000.0

    def epoch(self, t_ms: float) -> float:
        return time.time() + (t_ms - self.now_ms()) / 1000.0


def seeded_rng(*keys: Any) -> random.Random:
    """A ``random.Random`` seeded from ``keys`` (ints/strings) through BLAKE2b: the same keys give the same stream
    in every process (unlike ``hash``), so per-task draws do not depend on the order of events."""
    digest = hashlib.blake2b(repr(keys).encode(), digest_size=8).digest()
    return random.Random(int.from_bytes(digest, "little"))


@dataclass(frozen=True)
class Jitter:
    """Multiplicative jitter on a profiled execution time: ``factor`` is 1 for ``kind="none"``, ``exp(N(-σ²/2, σ))``
    for ``"lognormal"`` (mean 1, always positive), ``max(0.05, N(1, σ))`` for ``"normal"``. ``sigma`` is a fraction
    of the profile time (0.05 = 5 %)."""

    kind: str = "lognormal"
    sigma: float = 0.05

    def __post_init__(self) -> None:
        if self.kind not in ("none", "lognormal", "normal"):
            raise ValueError(f"jitter kind must be none, lognormal or normal, got {self.kind!r}")
        if not (self.sigma >= 0 and math.isfinite(self.sigma)):
            raise ValueError(f"jitter sigma must be a finite number >= 0, got {self.sigma!r}")

    @classmethod
    def parse(cls, spec: str) -> "Jitter":
        """``"none"``, ``"lognormal:0.1"`` or ``"normal:0.05"``. Raises ValueError naming the spec."""
        kind, _, sigma = spec.strip().partition(":")
        try:
            return cls(kind, float(sigma) if sigma else (0.0 if kind == "none" else 0.05))
        except ValueError as e:
            raise ValueError(f"jitter {spec!r}: {e}") from None

    def factor(self, rng: random.Random) -> float:
        if self.kind == "none" or self.sigma == 0:
            return 1.0
        if self.kind == "lognormal":
            return math.exp(rng.gauss(-self.sigma ** 2 / 2, self.sigma))
        return max(0.05, rng.gauss(1.0, self.sigma))

    def __str__(self) -> str:
        return "none" if self.kind == "none" else f"{self.kind}:{self.sigma:g}"


@dataclass(frozen=True)
class Episode:
    """Network variability episode: ``add_ms`` extra latency for tasks sent between ``start_s`` and ``end_s``
    (seconds since the run's start)."""

    start_s: float
    end_s: float
    add_ms: float


class NetworkModel:
    """Extra network latency (ms) of one cloud round trip, added to the cloud executor's hold.

    The workload's ``cloud_ms`` is the measured AWS Lambda round trip (network included), so the default adds
    nothing. Components (summed):

    * a base distribution: ``const:MS``, ``normal:MEAN,SD`` (truncated at 0), ``lognormal:MEDIAN,SIGMA``;
    * episodes ``+MS@T1-T2``: MS more for tasks sent between T1 and T2 seconds of the run (the paper's latency
      variability experiments inject such steps);
    * a random walk ``walk:STEP,MAX[,EVERY]``: every EVERY s (default 1) the offset moves by ±STEP ms, kept within
      [0, MAX]; the walk is seeded, so it is the same in every process.

    A task's draw is seeded by ``(seed, task key)``, so runs are reproducible whatever the order of events. Half of
    the latency is applied before execution (uplink, after the cloud's re-check: see the module docstring), half
    after (downlink).
    """

    _EPISODE = re.compile(r"^\+(?P<ms>\d+(\.\d*)?)@(?P<t1>\d+(\.\d*)?)-(?P<t2>\d+(\.\d*)?)$")

    def __init__(self, base: tuple = ("none",), episodes: Sequence[Episode] = (),
                 walk: tuple[float, float, float] | None = None, seed: int = 0) -> None:
        self.base = tuple(base)
        self.episodes = tuple(episodes)
        self.walk = walk
        self.seed = int(seed)
        self._walk_values: list[float] = [0.0]
        self._walk_rng = seeded_rng("walk", self.seed)

    @classmethod
    def parse(cls, specs: Iterable[str] | str | None, seed: int = 0) -> "NetworkModel":
        """Build from spec strings (see the class docstring; several may be given, comma- or list-separated).
        Raises ValueError naming a malformed spec."""
        if specs is None:
            specs = []
        if isinstance(specs, str):
            specs = [specs]
        items = [item for spec in specs for item in re.split(r"[;\s]+", spec.strip()) if item]
        base: tuple = ("none",)
        episodes, walk = [], None
        for s in items:
            try:
                if m := cls._EPISODE.match(s):
                    t1, t2 = float(m["t1"]), float(m["t2"])
                    if t2 <= t1:
                        raise ValueError("the episode must end after it starts")
                    episodes.append(Episode(t1, t2, float(m["ms"])))
                    continue
                kind, _, args = s.partition(":")
                vals = [float(v) for v in args.split(",")] if args else []
                if any(not math.isfinite(v) or v < 0 for v in vals):
                    raise ValueError("values must be finite numbers >= 0")
                if kind == "none" and not vals:
                    base = ("none",)
                elif kind == "const" and len(vals) == 1:
                    base = ("const", vals[0])
                elif kind == "normal" and len(vals) == 2:
                    base = ("normal", vals[0], vals[1])
                elif kind == "lognormal" and len(vals) == 2 and vals[0] > 0:
                    base = ("lognormal", vals[0], vals[1])
                elif kind == "walk" and len(vals) in (2, 3) and (len(vals) == 2 or vals[2] > 0):
                    walk = (vals[0], vals[1], vals[2] if len(vals) == 3 else 1.0)
                else:
                    raise ValueError("expected const:MS, normal:MEAN,SD, lognormal:MEDIAN,SIGMA, +MS@T1-T2 "
                                     "or walk:STEP,MAX[,EVERY]")
            except ValueError as e:
                raise ValueError(f"network-variability {s!r}: {e}") from None
        return cls(base, episodes, walk, seed)

    def describe(self) -> dict:
        return {"base": list(self.base), "episodes": [asdict(e) for e in self.episodes],
                "walk": None if self.walk is None else {"step_ms": self.walk[0], "max_ms": self.walk[1],
                                                        "every_s": self.walk[2]}}

    def offset_ms(self, t_ms: float) -> float:
        """The time-dependent part (episodes + random walk) at run time ``t_ms``."""
        t_s = t_ms / 1000.0
        extra = sum(e.add_ms for e in self.episodes if e.start_s <= t_s < e.end_s)
        if self.walk is not None and t_s > 0:
            step, vmax, every = self.walk
            i = int(t_s // every)
            while len(self._walk_values) <= i:
                v = self._walk_values[-1] + (step if self._walk_rng.random() < 0.5 else -step)
                self._walk_values.append(min(vmax, max(0.0, v)))
            extra += self._walk_values[i]
        return extra

    def sample(self, t_ms: float, rng: random.Random) -> float:
        """Extra round-trip latency (ms) for a task sent at run time ``t_ms``, drawn from ``rng``."""
        kind = self.base[0]
        if kind == "const":
            v = self.base[1]
        elif kind == "normal":
            v = max(0.0, rng.gauss(self.base[1], self.base[2]))
        elif kind == "lognormal":
            v = self.base[1] * math.exp(rng.gauss(0.0, self.base[2]))
        else:
            v = 0.0
        return v + self.offset_ms(t_ms)


class Samples:
    """A bounded sample of floats (a seeded reservoir beyond ``cap``) with percentiles, for latency statistics."""

    def __init__(self, cap: int = 200_000, seed: int = 0) -> None:
        self.cap = cap
        self.values: list[float] = []
        self.n = 0
        self.max = -math.inf
        self._rng = random.Random(seed)

    def add(self, v: float) -> None:
        self.n += 1
        if v > self.max:
            self.max = v
        if len(self.values) < self.cap:
            self.values.append(v)
        else:
            j = self._rng.randrange(self.n)
            if j < self.cap:
                self.values[j] = v

    def extend(self, values: Iterable[float]) -> None:
        for v in values:
            self.add(v)

    @staticmethod
    def summarize(values: Sequence[float], n: int | None = None, vmax: float | None = None) -> dict:
        """``{"n", "p01", "p50", "p99", "max", "mean"}`` of ``values`` (nearest-rank percentiles); zeros when empty."""
        if not values:
            return {"n": 0, "p01": 0.0, "p50": 0.0, "p99": 0.0, "max": 0.0, "mean": 0.0}
        s = sorted(values)

        def q(p: float) -> float:
            return s[min(len(s) - 1, max(0, math.ceil(p * len(s)) - 1))]

        return {"n": int(n if n is not None else len(s)), "p01": q(0.01), "p50": q(0.50), "p99": q(0.99),
                "max": float(vmax if vmax is not None else s[-1]), "mean": sum(s) / len(s)}

    def summary(self) -> dict:
        return self.summarize(self.values, self.n, self.max if self.n else None)


_FAILED = object()  # sentinel: a policy call raised


def _reason_key(reason: str) -> str:
    """A reason with its numbers replaced by '#', so drops can be counted by kind."""
    return re.sub(r"-?\d+(\.\d+)?", "#", reason)


# ================================================================================================ edge executors
class EdgeExecutor(abc.ABC):
    """Runs one task on the edge accelerator (the dispatcher runs one at a time).

    :meth:`run` is a coroutine on the dispatcher's loop; it returns ``(result, intended_ms)``: the model's output
    (or None) and, for emulated executors, the hold time it aimed for (None for real ones), which the dispatcher
    compares with the measured time to report the emulation's timing error. It raises on failure (the task ends
    FAILED with the error as reason)."""

    @abc.abstractmethod
    async def run(self, task: AnalyticsTask, workload: Workload, edge_id: str) -> tuple[Any, float | None]:
        ...

    def describe(self) -> dict:
        return {"kind": type(self).__name__}


class EmulatedEdgeExecutor(EdgeExecutor):
    """Holds the model's profile time on the edge: ``edge_ms`` x ``jitter.factor`` (seeded by ``(seed, edge_id,
    task_id)``), as an asyncio timer aimed at an absolute loop time (so loop delays do not accumulate)."""

    def __init__(self, jitter: Jitter = Jitter(), seed: int = 0) -> None:
        self.jitter = jitter
        self.seed = int(seed)

    async def run(self, task: AnalyticsTask, workload: Workload, edge_id: str) -> tuple[Any, float | None]:
        loop = asyncio.get_running_loop()
        start = loop.time()
        hold = workload[task.model].edge_ms * self.jitter.factor(seeded_rng(self.seed, "edge", edge_id, task.task_id))
        fut = loop.create_future()
        handle = loop.call_at(start + hold / 1000.0, _set_result_if_pending, fut, None)
        try:
            await fut
        finally:
            handle.cancel()
        return None, hold

    def describe(self) -> dict:
        return {"kind": "emulated", "jitter": str(self.jitter), "seed": self.seed}


def _set_result_if_pending(fut: asyncio.Future, value: Any) -> None:
    if not fut.done():
        fut.set_result(value)


class FramePayload:
    """A task payload of an application's frame path: ``frame`` ((H, W, 3) uint8 BGR ndarray, the camera's own
    object: never copied on the edge), ``meta`` (:class:`~aerodaas.models.FrameMeta`, sent to the cloud with the
    JPEG) and ``context`` (edge-side only: what the caller needs to hand the result on; never sent)."""

    __slots__ = ("frame", "meta", "context")

    def __init__(self, frame: Any, meta: Any = None, context: Any = None) -> None:
        self.frame, self.meta, self.context = frame, meta, context


def _frame_from_payload(payload: Any):
    """The frame of a task payload: an ``(H, W, 3)`` uint8 BGR array, from an ndarray, a :class:`FramePayload`, an
    ObjectRef to one, or JPEG bytes. Raises TypeError for anything else and ValueError for undecodable bytes."""
    import numpy as np

    if isinstance(payload, FramePayload):
        payload = payload.frame
    if payload is None:
        raise TypeError("the task has no frame (payload None); real executors need an image")
    if type(payload).__name__ == "ObjectRef":
        import ray

        payload = ray.get(payload)
    if isinstance(payload, (bytes, bytearray, memoryview)):
        import cv2

        img = cv2.imdecode(np.frombuffer(payload, dtype=np.uint8), cv2.IMREAD_COLOR)
        if img is None:
            raise ValueError("payload bytes are not a decodable JPEG/PNG image")
        return img
    if isinstance(payload, np.ndarray) and payload.ndim == 3 and payload.shape[2] == 3:
        return payload
    raise TypeError(f"payload must be an (H, W, 3) uint8 BGR array, an ObjectRef to one, or JPEG bytes; "
                    f"got {type(payload).__name__}")


class _DetectorBank:
    """Lazily built ONNX detectors by name, shared by the threads of one executor (one session per name and thread,
    since onnxruntime sessions are not meant to be shared across concurrent ``run`` calls)."""

    def __init__(self, detector_for: Mapping[str, str] | str, detector_kwargs: Mapping[str, Any] | None = None):
        self.detector_for = detector_for
        self.kwargs = dict(detector_kwargs or {})
        self._local = threading.local()

    def name_for(self, model: str) -> str:
        if isinstance(self.detector_for, str):
            return self.detector_for
        try:
            return self.detector_for[model]
        except KeyError:
            raise KeyError(f"no ONNX detector configured for model {model!r} (have {sorted(self.detector_for)})") \
                from None

    def detect(self, model: str, frame) -> list:
        from aerodaas.detect import make_detector

        cache = getattr(self._local, "cache", None)
        if cache is None:
            cache = self._local.cache = {}
        name = self.name_for(model)
        det = cache.get(name)
        if det is None:
            det = cache[name] = make_detector(name, **self.kwargs)
        return det.detect(frame)

    def run(self, model: str, frame, meta: Any = None) -> list:
        """The detections of ``model``'s detector on ``frame`` (``meta`` unused)."""
        return self.detect(model, frame)


class AnalyticsBank:
    """Runs an application's analytics objects (:class:`aerodaas.analytics.Analytics`) by model name, for the
    executors of scheduled analytics. Each thread gets its own copy of an analytics (``setup()`` once per copy), so
    an onnxruntime session is never shared by concurrent calls; with ``shared=True`` the given objects themselves
    are used, already set up by the caller (one executor thread: the edge host's own analytics). :meth:`run` returns ``process(frame, meta)`` and keeps the analytics'
    ``last_timing`` in ``self.last_timing`` of the thread (inference ms, when the analytics reports it)."""

    def __init__(self, analytics: Mapping[str, Any], shared: bool = False) -> None:
        if not analytics:
            raise ValueError("an AnalyticsBank needs at least one analytics (model name -> Analytics)")
        self.analytics = dict(analytics)
        self.shared = shared  # the caller has set the objects up (they live in its host)
        self._local = threading.local()

    def _get(self, model: str):
        try:
            proto = self.analytics[model]
        except KeyError:
            raise KeyError(f"no analytics for model {model!r} (have {sorted(self.analytics)})") from None
        if self.shared:
            return proto
        cache = getattr(self._local, "cache", None)
        if cache is None:
            cache = self._local.cache = {}
        obj = cache.get(model)
        if obj is None:
            import copy

            obj = cache[model] = copy.deepcopy(proto)
            obj.setup()
        return obj

    def run(self, model: str, frame, meta: Any = None) -> Any:
        """``process(frame, meta)`` of ``model``'s analytics on this thread; raises what it raises."""
        obj = self._get(model)
        out = obj.process(frame, meta)
        self._local.timing = dict(getattr(obj, "last_timing", None) or {})
        return out

    @property
    def last_timing(self) -> dict:
        """The ``last_timing`` of the analytics that last ran on this thread (empty if it reports none)."""
        return getattr(self._local, "timing", {})


class OnnxEdgeExecutor(EdgeExecutor):
    """Runs a real ONNX detector on the task's frame on one worker thread (the edge's one accelerator).

    ``detector_for``: the detector name for every workload model (``"yolox_nano"``, ``"nanodet_plus_m_416"``) or a
    mapping model -> name (the workload's models are stand-ins: any model may be mapped to either detector).
    ``detector_kwargs`` go to :func:`aerodaas.detect.make_detector` (``model_path``, ``score_threshold``, ...).
    The payload is an ndarray, an ObjectRef to one (same node: zero-copy), or JPEG bytes. The result is the list of
    :class:`~aerodaas.models.Detection`.
    """

    def __init__(self, detector_for: Mapping[str, str] | str = "yolox_nano",
                 detector_kwargs: Mapping[str, Any] | None = None) -> None:
        self.bank = _DetectorBank(detector_for, detector_kwargs)
        self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="edge-onnx")

    async def run(self, task: AnalyticsTask, workload: Workload, edge_id: str) -> tuple[Any, float | None]:
        payload = task.payload
        loop = asyncio.get_running_loop()
        dets = await loop.run_in_executor(self._pool, lambda: self.bank.detect(task.model, _frame_from_payload(payload)))
        return dets, None

    def describe(self) -> dict:
        return {"kind": "onnx", "detectors": self.bank.detector_for}


class AnalyticsEdgeExecutor(EdgeExecutor):
    """Runs an application's analytics on the edge, one task at a time on one worker thread (the edge's one
    accelerator): ``bank.run(task.model, frame, meta)`` for a :class:`FramePayload`. The result is the analytics'
    output (e.g. a list of :class:`~aerodaas.models.Detection`); ``last_timing`` of the analytics goes to
    ``task.notes["timing"]``."""

    def __init__(self, bank: AnalyticsBank) -> None:
        self.bank = bank
        self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="edge-analytics")

    async def run(self, task: AnalyticsTask, workload: Workload, edge_id: str) -> tuple[Any, float | None]:
        payload = task.payload
        meta = getattr(payload, "meta", None)

        def work():
            out = self.bank.run(task.model, _frame_from_payload(payload), meta)
            task.notes["timing"] = self.bank.last_timing
            return out

        return await asyncio.get_running_loop().run_in_executor(self._pool, work), None

    def describe(self) -> dict:
        return {"kind": "analytics", "models": sorted(self.bank.analytics)}


# ================================================================================================ cloud executor
def _where() -> dict:
    """``pid`` and, inside a Ray worker, the ``node_id`` and node ``labels`` of this process."""
    out: dict[str, Any] = {"pid": os.getpid(), "node_id": None, "labels": {}}
    ray = sys.modules.get("ray")  # not imported here: outside Ray there is nothing to ask (and it takes seconds)
    try:
        if ray is not None and ray.is_initialized():
            ctx = ray.get_runtime_context()
            out["node_id"] = ctx.get_node_id()
            out["labels"] = dict(ctx.get_node_labels())
    except Exception:  # informational only
        pass
    return out


class CloudExecutor:
    """The cloud side: runs tasks sent by :class:`CloudPool` clients, any number at once (like AWS Lambda).

    Requests (dicts) carry: ``k`` (the client's key), ``model``, ``sent`` (epoch s), ``up_ms``/``down_ms`` (emulated
    network latency before/after execution), ``exec_ms`` (emulated hold; None in real mode), ``admit_by`` (epoch s or
    None: the re-check), ``jpeg`` (real mode: the frame), ``meta`` (its FrameMeta or None). The executor re-checks
    ``now <= admit_by`` when the request arrives, waits until ``sent + up_ms``, runs the model (emulated: holds
    ``exec_ms``; real: decodes the JPEG and runs the ONNX detector on one of ``threads`` threads, re-checking when a
    thread picks the task up, not counting ``up_ms``), waits ``down_ms`` and queues the reply for the client's
    :meth:`collect`.

    Replies (dicts): ``k``, ``ok`` (False: refused by the re-check, or failed: see ``error``), ``start``/``end`` (epoch
    s of the model's execution), ``result`` (real mode: list of detections), ``ready`` (epoch s), ``error``.

    ``detector_for``/``detector_kwargs`` as in :class:`OnnxEdgeExecutor` (real mode only). ``analytics`` (real mode):
    model name -> an application's :class:`~aerodaas.analytics.Analytics`, run instead of the ONNX detectors (a copy
    per thread, ``process(frame, meta)`` with the request's ``meta``: the scheduled analytics of a running app).
    Wrapped as the Ray actor
    :data:`CloudExecutorActor`; also usable in-process (tests, single-process experiments).
    """

    def __init__(self, name: str = "cloud", mode: str = "emulated", threads: int = 2,
                 detector_for: Mapping[str, str] | str = "yolox_nano",
                 detector_kwargs: Mapping[str, Any] | None = None,
                 analytics: Mapping[str, Any] | None = None) -> None:
        if mode not in ("emulated", "real"):
            raise ValueError(f"mode must be 'emulated' or 'real', got {mode!r}")
        if int(threads) < 1:
            raise ValueError(f"threads must be >= 1, got {threads!r}")
        if analytics and mode != "real":
            raise ValueError("analytics run in mode 'real' only")
        self.name = name
        self.mode = mode
        self._bank = (AnalyticsBank(analytics) if analytics else _DetectorBank(detector_for, detector_kwargs)) \
            if mode == "real" else None
        self._pool = concurrent.futures.ThreadPoolExecutor(int(threads), thread_name_prefix="cloud-onnx") \
            if mode == "real" else None
        self._ready: dict[str, list[dict]] = defaultdict(list)
        self._events: dict[str, asyncio.Event] = {}
        self._handles: dict[str, set] = defaultdict(set)
        self.executed = 0
        self.refused = 0
        self._loop: asyncio.AbstractEventLoop | None = None

    # ---- API
    async def info(self) -> dict:
        """Where this executor runs: ``name``, ``mode``, ``pid``, and (inside Ray) ``node_id`` and ``labels``."""
        return {"name": self.name, "mode": self.mode, **_where()}

    async def submit(self, client: str, reqs: list[dict]) -> int:
        """Accept a batch of requests from ``client``; returns how many were accepted (all)."""
        loop = self._loop = asyncio.get_running_loop()
        wall, lt = time.time(), loop.time()
        for req in reqs:  # arrival: the re-check comes before the emulated uplink (see the module docstring)
            self._arrive(client, req, loop, wall, lt)
        return len(reqs)

    async def collect(self, client: str, max_wait_s: float = 5.0) -> list[dict]:
        """Long poll: every reply ready for ``client``, as soon as there is at least one (or ``[]`` after
        ``max_wait_s`` seconds)."""
        ev = self._event(client)
        if not self._ready[client]:
            ev.clear()
            try:
                await asyncio.wait_for(ev.wait(), max_wait_s)
            except asyncio.TimeoutError:
                return []
        out, self._ready[client] = self._ready[client], []
        return out

    async def reset(self, client: str | None = None) -> None:
        """Forget ``client``'s (or every client's) pending work and replies."""
        for c in ([client] if client is not None else list(self._handles)):
            for h in self._handles.pop(c, ()):
                h.cancel()
            self._ready.pop(c, None)

    async def stats(self) -> dict:
        return {"name": self.name, "executed": self.executed, "refused": self.refused}

    # ---- internals
    def _event(self, client: str) -> asyncio.Event:
        ev = self._events.get(client)
        if ev is None:
            ev = self._events[client] = asyncio.Event()
        return ev

    def _later(self, client: str, loop, when: float, fn, *args) -> None:
        handles = self._handles[client]
        box: list = []

        def run() -> None:
            handles.discard(box[0])
            fn(*args)

        h = loop.call_at(when, run)
        box.append(h)
        handles.add(h)

    def _reply(self, client: str, req: dict, ok: bool, start: float | None, end: float | None,
               result: Any = None, error: str | None = None, due: float | None = None) -> None:
        self._ready[client].append({"k": req["k"], "ok": ok, "start": start, "end": end, "result": result,
                                    "error": error, "ready": time.time(), "due": due})
        self._event(client).set()

    def _refused(self, client: str, req: dict, now: float) -> bool:
        admit_by = req.get("admit_by")
        if admit_by is not None and now > admit_by:
            self.refused += 1
            self._reply(client, req, False, None, None,
                        error=f"cloud re-check: start {1000 * (now - admit_by):.0f} ms past the admit-by time")
            return True
        return False

    def _arrive(self, client: str, req: dict, loop, now: float, lt: float) -> None:
        if self._refused(client, req, now):
            return
        if self.mode == "real":  # the model starts after the emulated uplink (at once when there is none)
            self._later(client, loop, lt + (req["sent"] + req["up_ms"] / 1000.0 - now), self._start_real, client, req)
            return
        self.executed += 1
        # emulated: the hold ends on the intended schedule (sent + uplink + exec), so a late arrival of the request
        # (a Ray hop delayed by CPU contention) is absorbed; the reply is due after the downlink and is sent
        # ``lead_ms`` early (the client releases it at ``due``)
        start = max(now, req["sent"] + req["up_ms"] / 1000.0)
        end = max(now, req["sent"] + (req["up_ms"] + req["exec_ms"]) / 1000.0)
        due = end + req["down_ms"] / 1000.0
        send_at = max(now, due - req.get("lead_ms", 0.0) / 1000.0)
        self._later(client, loop, lt + (send_at - now), self._reply, client, req, True, start, end, None, None, due)

    def _start_real(self, client: str, req: dict) -> None:
        fut = asyncio.get_running_loop().run_in_executor(self._pool, self._run_real, req)
        fut.add_done_callback(lambda f: self._real_done(client, req, f))

    def _run_real(self, req: dict) -> tuple[str, float | None, float | None, Any]:
        start = time.time()
        admit_by = req.get("admit_by")
        if admit_by is not None and start - req["up_ms"] / 1000.0 > admit_by:  # queued for a detector thread too long
            return "refused", start, None, None
        self.executed += 1
        out = self._bank.run(req["model"], _frame_from_payload(req["jpeg"]), req.get("meta"))
        return "ok", start, time.time(), out

    def _real_done(self, client: str, req: dict, fut) -> None:
        try:
            status, start, end, result = fut.result()
        except Exception as e:  # the model failed: a FAILED task, reported with its error
            self._reply(client, req, False, None, None, error=f"cloud execution failed: {type(e).__name__}: {e}")
            return
        if status == "refused":
            self.refused += 1
            self._reply(client, req, False, None, None,
                        error=f"cloud re-check: queued {1000 * (start - req['up_ms'] / 1000.0 - req['admit_by']):.0f} ms "
                              "past the admit-by time")
            return
        loop = self._loop
        self._later(client, loop, loop.time() + req["down_ms"] / 1000.0,
                    self._reply, client, req, True, start, end, result)


def _ray_remote(cls, **options):
    import ray

    return ray.remote(**options)(cls)


class _LazyActorClass:
    """``ray.remote`` applied on first use, so importing this module does not import Ray."""

    def __init__(self, cls, **options) -> None:
        self._cls, self._options, self._actor = cls, options, None

    def _get(self):
        if self._actor is None:
            self._actor = _ray_remote(self._cls, **self._options)
        return self._actor

    def options(self, **kw):
        return self._get().options(**kw)

    def remote(self, *a, **kw):
        return self._get().remote(*a, **kw)


#: Ray actor class of :class:`CloudExecutor` (an async actor; place it with ``label_selector={"tier": "cloud"}``).
CloudExecutorActor = _LazyActorClass(CloudExecutor, num_cpus=0, max_concurrency=1000, max_restarts=0)


def cloud_selector(has_cloud_nodes: bool) -> dict[str, str]:
    """``{"tier": "cloud"}``, or ``{"tier": "in(edge,cloud)"}`` on a cluster without cloud nodes (local mode)."""
    return {"tier": "cloud"} if has_cloud_nodes else {"tier": "in(edge,cloud)"}


def start_cloud_executors(n: int, mode: str = "emulated", *, selector: Mapping[str, str] | None = None,
                          name_prefix: str = "cloud", threads: int = 2, spread: bool = True,
                          detector_for: Mapping[str, str] | str = "yolox_nano",
                          detector_kwargs: Mapping[str, Any] | None = None,
                          analytics: Mapping[str, Any] | None = None) -> list:
    """Start ``n`` :data:`CloudExecutorActor` s on tier=cloud nodes (``selector`` defaults to
    :func:`cloud_selector` for the current cluster), spread over the nodes that match. Returns the handles once
    each has answered :meth:`CloudExecutor.info`. Raises ValueError for ``n < 1``."""
    import ray

    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if selector is None:
        selector = cloud_selector(any(x.get("Alive") and x.get("Labels", {}).get("tier") == "cloud"
                                      for x in ray.nodes()))
    opts: dict[str, Any] = {"label_selector": dict(selector)}
    if spread:
        opts["scheduling_strategy"] = "SPREAD"
    handles = [CloudExecutorActor.options(**opts).remote(f"{name_prefix}{i}", mode, threads, detector_for,
                                                          detector_kwargs, analytics) for i in range(n)]
    ray.get([h.info.remote() for h in handles])
    return handles


# ================================================================================================ cloud pool (edge side)
@dataclass
class _InFlight:
    dispatcher: "AnalyticsDispatcher"
    task: AnalyticsTask
    executor: int
    sent_ms: float
    intended_ms: float | None
    admit_by_ms: float
    retried: bool = False
    req: dict = field(default_factory=dict)


class CloudPool:
    """Edge-side client of a set of cloud executors, shared by the dispatchers of one process (one event loop).

    ``executors``: Ray actor handles of :data:`CloudExecutorActor` or in-process :class:`CloudExecutor` objects.
    ``mode``: "emulated" (holds ``cloud_ms`` x ``jitter``) or "real" (frames are JPEG-encoded with OpenCV at
    ``jpeg_quality`` and run by the executor's ONNX model). ``network``: the emulated extra latency
    (:class:`NetworkModel`, used in both modes). ``retry``: retry a task once on a surviving executor when its
    executor dies (if the policy still admits it). ``lost_after_ms``: a task with no reply this long after its
    deadline ends FAILED. ``reply_lead_ms`` (emulated mode): the executor sends a reply up to this long before it
    is due and the pool releases it exactly when due (unless the executor died meanwhile), so Ray's reply hop does
    not add to the emulated round trip; 0 makes the reply's arrival time the completion time. See the module
    docstring for the transport and the loss handling.
    """

    def __init__(self, executors: Sequence[Any], *, mode: str = "emulated", network: NetworkModel | None = None,
                 jitter: Jitter = Jitter("lognormal", 0.1), seed: int = 0, retry: bool = True,
                 lost_after_ms: float = 10_000.0, jpeg_quality: int = 90, client_id: str | None = None,
                 reply_lead_ms: float = 100.0) -> None:
        if mode not in ("emulated", "real"):
            raise ValueError(f"mode must be 'emulated' or 'real', got {mode!r}")
        if not (reply_lead_ms >= 0 and math.isfinite(reply_lead_ms)):
            raise ValueError(f"reply_lead_ms must be a finite number >= 0, got {reply_lead_ms!r}")
        self.reply_lead_ms = float(reply_lead_ms)
        if not executors:
            raise ValueError("a CloudPool needs at least one cloud executor")
        self.executors = list(executors)
        self.mode = mode
        self.network = network or NetworkModel()
        self.jitter = jitter
        self.seed = int(seed)
        self.retry = retry
        self.lost_after_ms = float(lost_after_ms)
        self.jpeg_quality = int(jpeg_quality)
        self.client = client_id or f"pool-{os.getpid()}-{id(self):x}-{time.time_ns() % 10**9}"
        self.alive = [True] * len(self.executors)
        self.infos: list[dict] = [{} for _ in self.executors]
        self.events: list[dict] = []
        self.dispatchers: list[AnalyticsDispatcher] = []
        self.clock: Clock | None = None
        self.rtt_error = Samples()
        self.reply_margin = Samples()
        self._inflight: dict[int, _InFlight] = {}
        self._outbox: dict[int, list[dict]] = defaultdict(list)
        self._flush_scheduled = False
        self._keys = itertools.count(1)
        self._rr = itertools.count()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._tasks: list[asyncio.Task] = []
        self._encoder: concurrent.futures.ThreadPoolExecutor | None = None
        self.sent = 0
        self.retried = 0

    @staticmethod
    def _is_actor(ex: Any) -> bool:
        return hasattr(getattr(ex, "submit", None), "remote")

    async def _call(self, i: int, method: str, *args):
        ex = self.executors[i]
        if self._is_actor(ex):
            return await getattr(ex, method).remote(*args)
        return await getattr(ex, method)(*args)

    # ---- lifecycle
    async def start(self, clock: Clock | None = None) -> None:
        """Bind to the running loop, ask every executor where it runs, start the reply collectors and the watchdog.
        Idempotent."""
        if self._loop is not None:
            return
        self._loop = asyncio.get_running_loop()
        self.clock = clock or Clock()
        infos = await asyncio.gather(*(self._call(i, "info") for i in range(len(self.executors))),
                                     return_exceptions=True)
        for i, info in enumerate(infos):
            if isinstance(info, BaseException):
                self.alive[i] = False
                self.events.append({"executor": i, "name": f"#{i}", "node_id": None, "at_s": 0.0,
                                    "error": f"{type(info).__name__}: {info}", "in_flight": 0, "retried": 0,
                                    "failed": 0})
            else:
                self.infos[i] = info
        for i in range(len(self.executors)):
            if self.alive[i]:
                self._tasks.append(self._loop.create_task(self._collector(i)))
        self._tasks.append(self._loop.create_task(self._watchdog()))
        if self.mode == "real":
            self._encoder = concurrent.futures.ThreadPoolExecutor(2, thread_name_prefix="jpeg")

    async def close(self) -> None:
        """Stop collecting and forget this client's work on the executors that are still alive."""
        for t in self._tasks:
            t.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._tasks.clear()
        await asyncio.gather(*(self._call(i, "reset", self.client) for i in range(len(self.executors))
                               if self.alive[i]), return_exceptions=True)
        if self._encoder is not None:
            self._encoder.shutdown(wait=False)

    def attach(self, dispatcher: "AnalyticsDispatcher") -> None:
        self.dispatchers.append(dispatcher)

    async def add_executor(self, executor: Any) -> dict:
        """Add a cloud executor (e.g. on a replacement cloud node) to a started pool; if no executor was alive,
        every dispatcher's policy hears ``on_cloud_availability(True)``. Returns the executor's info; raises
        whatever asking it for its info raises (then nothing is added)."""
        i = len(self.executors)
        self.executors.append(executor)
        try:
            info = await self._call(i, "info")
        except BaseException:
            self.executors.pop()
            raise
        was_available = self.available
        self.alive.append(True)
        self.infos.append(info)
        self._tasks.append(self._loop.create_task(self._collector(i)))
        if not was_available:
            for d in list(self.dispatchers):
                d._on_cloud_availability(True)
        return info

    @property
    def available(self) -> bool:
        return any(self.alive)

    def in_flight(self, dispatcher: "AnalyticsDispatcher | None" = None) -> int:
        return sum(1 for f in self._inflight.values() if dispatcher is None or f.dispatcher is dispatcher)

    def name_of(self, i: int) -> str:
        return self.infos[i].get("name") or f"#{i}"

    # ---- sending
    def _pick(self) -> int | None:
        alive = [i for i, a in enumerate(self.alive) if a]
        if not alive:
            return None
        return alive[next(self._rr) % len(alive)]

    def send(self, dispatcher: "AnalyticsDispatcher", task: AnalyticsTask, admit_by_ms: float, now_ms: float) -> bool:
        """Queue ``task`` for the cloud (on the loop). Returns False when no executor is alive."""
        i = self._pick()
        if i is None:
            return False
        key = next(self._keys)
        profile = dispatcher.workload[task.model]
        rng = seeded_rng(self.seed, "cloud", dispatcher.edge_id, task.task_id)
        net = self.network.sample(now_ms, rng)
        exec_ms = profile.cloud_ms * self.jitter.factor(rng) if self.mode == "emulated" else None
        req = {"k": key, "model": task.model, "sent": time.time(), "up_ms": net / 2.0, "down_ms": net / 2.0,
               "exec_ms": exec_ms, "lead_ms": self.reply_lead_ms,
               "admit_by": None if math.isinf(admit_by_ms) else self.clock.epoch(admit_by_ms), "jpeg": None,
               "meta": getattr(task.payload, "meta", None)}
        f = _InFlight(dispatcher, task, i, now_ms, None if exec_ms is None else exec_ms + net, admit_by_ms, req=req)
        self._inflight[key] = f
        self.sent += 1
        if self.mode == "real":
            self._loop.create_task(self._encode_then_queue(key, task.payload))
        else:
            self._queue(i, req)
        return True

    async def _encode_then_queue(self, key: int, payload: Any) -> None:
        f = self._inflight.get(key)
        if f is None:
            return
        try:
            if isinstance(payload, (bytes, bytearray)):
                f.req["jpeg"] = bytes(payload)
            else:
                f.req["jpeg"] = await self._loop.run_in_executor(self._encoder, self._encode, payload)
        except Exception as e:
            self._finish_failed(key, f"cannot JPEG-encode the frame: {type(e).__name__}: {e}")
            return
        f.req["sent"] = time.time()
        if self.alive[f.executor]:
            self._queue(f.executor, f.req)
        else:
            self._reroute_or_fail(key, f"cloud executor {self.name_of(f.executor)} is gone")

    def _encode(self, payload: Any) -> bytes:
        import cv2

        frame = _frame_from_payload(payload)
        ok, buf = cv2.imencode(".jpg", frame, [int(cv2.IMWRITE_JPEG_QUALITY), self.jpeg_quality])
        if not ok:
            raise ValueError("cv2.imencode failed")
        return buf.tobytes()

    def _queue(self, i: int, req: dict) -> None:
        self._outbox[i].append(req)
        if not self._flush_scheduled:
            self._flush_scheduled = True
            self._loop.call_soon(self._flush)

    def _flush(self) -> None:
        self._flush_scheduled = False
        boxes, self._outbox = self._outbox, defaultdict(list)
        for i, reqs in boxes.items():
            if not reqs:
                continue
            if not self.alive[i]:
                for r in reqs:
                    self._reroute_or_fail(r["k"], f"cloud executor {self.name_of(i)} died before the task was sent")
                continue
            ex = self.executors[i]
            if self._is_actor(ex):
                # fire and forget: if the executor is dead, its outstanding collect call fails and every task sent
                # to it (these included) is retried or failed by _executor_died
                ex.submit.remote(self.client, reqs)
            else:
                self._loop.create_task(ex.submit(self.client, reqs))

    # ---- replies
    async def _collector(self, i: int) -> None:
        while self.alive[i]:
            try:
                replies = await self._call(i, "collect", self.client)
            except asyncio.CancelledError:
                raise
            except Exception as e:
                self._executor_died(i, e)
                return
            for r in replies:
                self._on_reply(i, r)

    def _on_reply(self, i: int, r: dict) -> None:
        f = self._inflight.get(r["k"])
        if f is None or f.executor != i:  # already given up on (watchdog), or rerouted
            return
        due = r.get("due")
        if due is not None:
            wait = due - time.time()
            self.reply_margin.add(wait * 1000.0)
            if wait > 0:  # an early (lead) reply: release it when due, if the executor is still alive then
                self._loop.call_at(self._loop.time() + wait, self._release, i, r)
                return
        self._release(i, r)

    def _release(self, i: int, r: dict) -> None:
        f = self._inflight.get(r["k"])
        if f is None or f.executor != i:  # failed/rerouted meanwhile (executor death)
            return
        del self._inflight[r["k"]]
        now = f.dispatcher.clock.now_ms()
        latency = now - f.sent_ms
        if f.intended_ms is not None and r["ok"]:
            self.rtt_error.add(latency - f.intended_ms)
        f.dispatcher._on_cloud_reply(f.task, r, latency, self.name_of(i))

    def _finish_failed(self, key: int, reason: str) -> None:
        f = self._inflight.pop(key, None)
        if f is None:
            return
        now = f.dispatcher.clock.now_ms()
        f.dispatcher._on_cloud_reply(f.task, {"ok": False, "error": reason, "failed": True}, now - f.sent_ms, None)

    def _reroute_or_fail(self, key: int, why: str) -> str:
        """Retry ``key`` on a surviving executor if allowed and the policy still admits it; else FAILED."""
        f = self._inflight.get(key)
        if f is None:
            return "gone"
        d = f.dispatcher
        now = d.clock.now_ms()
        if self.retry and not f.retried and self.available and d._admits(f.task, now):
            j = self._pick()
            f.executor, f.retried = j, True
            f.req["sent"] = time.time()
            f.req["admit_by"] = None if math.isinf(f.admit_by_ms) else self.clock.epoch(f.admit_by_ms)
            f.intended_ms = None  # the retried round trip is not compared with the emulation's intention
            self.retried += 1
            if f.req.get("jpeg") is None and self.mode == "real":
                self._loop.create_task(self._encode_then_queue(key, f.task.payload))
            else:
                self._queue(j, f.req)
            return "retried"
        self._finish_failed(key, why)
        return "failed"

    def _executor_died(self, i: int, exc: BaseException) -> None:
        if not self.alive[i]:
            return
        self.alive[i] = False
        now_ms = self.clock.now_ms()
        keys = [k for k, f in self._inflight.items() if f.executor == i]
        info = self.infos[i]
        ev = {"executor": i, "name": self.name_of(i), "node_id": info.get("node_id"), "at_s": now_ms / 1000.0,
              "error": f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}",
              "in_flight": len(keys), "retried": 0, "failed": 0}
        node = (info.get("node_id") or "?")[:12]
        if not self.available:  # first: a policy reacting to the failures below must already know there is no cloud
            for d in list(self.dispatchers):
                d._on_cloud_availability(False)
        for k in keys:
            outcome = self._reroute_or_fail(k, f"cloud executor {ev['name']} (node {node}) died at "
                                               f"{now_ms / 1000:.1f} s while the task was in flight")
            if outcome in ("retried", "failed"):
                ev[outcome] += 1
        self.events.append(ev)
        log.warning("cloud executor %s on node %s died at %.1f s: %d in flight (%d retried, %d failed)",
                    ev["name"], node, ev["at_s"], ev["in_flight"], ev["retried"], ev["failed"])

    async def _watchdog(self) -> None:
        while True:
            await asyncio.sleep(0.5)
            for k, f in list(self._inflight.items()):
                if f.dispatcher.clock.now_ms() > max(f.task.deadline_ms, f.sent_ms) + self.lost_after_ms:
                    self._finish_failed(k, f"no reply from the cloud {self.lost_after_ms / 1000:.0f} s after the "
                                           "deadline")

    def report(self) -> dict:
        return {"executors": [{"name": self.name_of(i), "node_id": self.infos[i].get("node_id"),
                               "labels": self.infos[i].get("labels", {}), "alive": self.alive[i]}
                              for i in range(len(self.executors))],
                "losses": list(self.events), "sent": self.sent, "retried": self.retried,
                "in_flight": len(self._inflight), "mode": self.mode, "network": self.network.describe(),
                "jitter": str(self.jitter), "reply_lead_ms": self.reply_lead_ms,
                "reply_margin_ms": self.reply_margin.summary()}


# ================================================================================================ dispatcher
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
            self._owns_cloud = self.cloud._loop is None
            await self.cloud.start(self.clock)
            if not self.cloud.available:
                self._on_cloud_availability(False)
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
        with self._lock:
            out = fn(*args)
        us = (time.perf_counter_ns() - t0) / 1000.0
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

    def _admits(self, task: AnalyticsTask, now_ms: float) -> bool:
        return bool(self._safe("cloud_admit", False, task, now_ms, about=f"#{task.task_id}"))

    def _admit_by(self, task: AnalyticsTask, now_ms: float) -> float | None:
        return admit_by_time(lambda t: self._admits(task, t), now_ms, task.deadline_ms)

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

    def _on_cloud_reply(self, task: AnalyticsTask, reply: dict, latency_ms: float, executor: str | None) -> None:
        """A cloud reply (or a failure) for ``task``: set its terminal state, then tell the policy."""
        if task.state is not TaskState.PENDING:
            return
        now = self.clock.now_ms()
        if reply.get("ok"):
            state = TaskState.DONE_ON_TIME if now <= task.deadline_ms else TaskState.DONE_LATE
            task.result = reply.get("result")
            self._finish(task, state, "cloud", task.reason or "cloud", notify=False)
        elif reply.get("failed") or not str(reply.get("error", "")).startswith("cloud re-check"):
            self._finish(task, TaskState.FAILED, "cloud", reply.get("error") or "cloud failure", notify=False)
        else:
            self._finish(task, TaskState.DROPPED_TIME, "cloud", reply["error"], notify=False)
        self.cloud_counters.on_end(task, now)
        decisions = self._safe("on_cloud_done", [], task, now, latency_ms, about=f"#{task.task_id}")
        self._notify(task)
        self._after_policy(decisions)

    def _on_cloud_availability(self, available: bool) -> None:
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
                self._finish(task, TaskState.FAILED, "edge", error, notify=False)
            else:
                self._finish(task, TaskState.DONE_ON_TIME if now <= task.deadline_ms else TaskState.DONE_LATE,
                             "edge", task.reason or "edge", notify=False)
            decisions = self._safe("on_edge_done", [], task, now, exec_ms, about=f"#{task.task_id}")
            self._notify(task)
            self._apply(decisions)
            self._rearm_poll()

    # ------------------------------------------------------------------ terminal states
    def _finish(self, task: AnalyticsTask, state: TaskState, tier: str | None, reason: str,
                notify: bool = True) -> None:
        if task.state is not TaskState.PENDING:
            self._policy_error(f"task #{task.task_id} would end twice ({task.state.value}, then {state.value})")
            return
        task.state = state
        if tier is not None:
            task.tier = tier
        task.reason = reason
        task.end_ms = self.clock.now_ms()
        profile = self.workload[task.model]
        u = task_utility(task, profile)
        self.utility += u
        self.utility_by_model[task.model] += u
        self.count_by_model[task.model] += 1
        if state is TaskState.DONE_ON_TIME:
            self.ontime_by_model[task.model] += 1
        charged = state in _DONE_STATES or state is TaskState.FAILED
        if charged and task.tier == "cloud":
            self.cloud_cost += profile.cloud_cost
        elif charged and task.tier == "edge":
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
            for k, f in list(self.cloud._inflight.items()):
                if f.dispatcher is self:
                    self.cloud._finish_failed(k, "run ended while in flight on the cloud")
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


# ================================================================================================ edge host (Ray actor)
class EdgeHost:
    """Hosts several :class:`AnalyticsDispatcher` s (one per edge device) and one shared :class:`CloudPool` on one
    asyncio loop: a Ray async actor (:data:`EdgeHostActor`, place it with ``label_selector={"tier": "edge"}``).

    Hosting many emulated edge devices in one process keeps memory and CPU sane (the tasks are timers). The
    benchmark configures a run (:meth:`configure`), replays a seeded arrival trace (:meth:`run_trace`) and reads
    the per-device reports. :meth:`submit` is the live entry point (a frame path in another actor).
    """

    def __init__(self, name: str = "edge-host") -> None:
        self.name = name
        self.dispatchers: dict[str, AnalyticsDispatcher] = {}
        self.pool: CloudPool | None = None
        self.clock: Clock | None = None

    async def info(self) -> dict:
        """Where this host runs: ``name``, ``pid``, ``node_id``, node ``labels``."""
        return {"name": self.name, **_where()}

    async def configure(self, *, scheduler: str, workload: Workload, edge_ids: Sequence[str],
                        cloud_executors: Sequence[Any] = (), start_epoch: float | None = None,
                        mode: str = "emulated", edge_jitter: str = "lognormal:0.05",
                        cloud_jitter: str = "lognormal:0.1", network: Sequence[str] | str | None = None,
                        seed: int = 0, retry: bool = True, scheduler_kwargs: Mapping[str, Any] | None = None,
                        detector_for: Mapping[str, str] | str = "yolox_nano", reply_lead_ms: float = 100.0) -> dict:
        """Create one dispatcher with a fresh ``scheduler`` policy per edge id, sharing a new cloud pool over
        ``cloud_executors`` (none: edge-only). ``start_epoch``: the run's time origin (epoch s), shared by every
        host of a run. Raises ValueError (unknown scheduler, bad specs) before anything starts."""
        from aerodaas.schedulers.analytics_base import make_analytics_scheduler

        await self.close()
        policies = {e: make_analytics_scheduler(scheduler, workload, **dict(scheduler_kwargs or {})) for e in edge_ids}
        ej, cj = Jitter.parse(edge_jitter), Jitter.parse(cloud_jitter)
        net = NetworkModel.parse(network, seed)
        self.clock = Clock.at_epoch(start_epoch) if start_epoch is not None else Clock()
        self.pool = CloudPool(list(cloud_executors), mode=mode, network=net, jitter=cj, seed=seed, retry=retry,
                              client_id=f"{self.name}-{scheduler}-{time.time_ns()}", reply_lead_ms=reply_lead_ms) \
            if cloud_executors else None
        for e in edge_ids:
            edge = EmulatedEdgeExecutor(ej, seed) if mode == "emulated" else OnnxEdgeExecutor(detector_for)
            self.dispatchers[e] = AnalyticsDispatcher(policies[e], edge, self.pool, edge_id=e, clock=self.clock,
                                                      keep_tasks=False, sample_seed=seed)
        for d in self.dispatchers.values():
            await d.start()
        return {"edges": list(self.dispatchers), "cloud": self.pool.report() if self.pool else None}

    async def submit(self, edge_id: str, drone: str, model: str, payload: Any = None,
                     arrival_ms: float | None = None) -> int:
        """Submit one task to the dispatcher of ``edge_id`` (KeyError naming the known edges otherwise)."""
        try:
            d = self.dispatchers[edge_id]
        except KeyError:
            raise KeyError(f"unknown edge {edge_id!r}; this host has {sorted(self.dispatchers)}") from None
        return d.submit(drone, model, payload, arrival_ms)

    async def run_trace(self, trace: Sequence[tuple[float, str, str, str]], drain_timeout_s: float = 10.0,
                        samples: bool = True) -> dict:
        """Replay ``trace`` rows ``(arrival_ms, edge_id, drone, model)`` (sorted by time, on the run's clock) as
        wall-clock arrivals, then finish every dispatcher. Returns ``{"edges": [report, ...], "cloud": pool
        report}``. Arrivals are submitted with their scheduled time; how late the replay delivered them is reported
        as ``arrival_lateness``."""
        loop = asyncio.get_running_loop()
        for group_t, rows in itertools.groupby(trace, key=lambda r: r[0]):
            delay = self.clock.loop_time(loop, group_t) - loop.time()
            if delay > 0:
                fut = loop.create_future()
                loop.call_at(loop.time() + delay, _set_result_if_pending, fut, None)
                await fut
            for t_ms, edge_id, drone, model in rows:
                self.dispatchers[edge_id].submit(drone, model, None, t_ms)
        reports = await asyncio.gather(*(d.finish(drain_timeout_s) for d in self.dispatchers.values()))
        if samples:
            reports = [d.report(samples=True) for d in self.dispatchers.values()]
        out = {"edges": reports, "cloud": self.pool.report() if self.pool else None,
               "cloud_rtt_error_ms": self.pool.rtt_error.values if self.pool else [],
               "cloud_reply_margin_ms": self.pool.reply_margin.values if self.pool else []}
        return out

    async def close(self) -> None:
        """Finish any dispatcher still running and release the cloud pool."""
        for d in self.dispatchers.values():
            if d._loop is not None and not d._closed:
                await d.finish(0.0)
        self.dispatchers = {}
        if self.pool is not None:
            await self.pool.close()
            self.pool = None


#: Ray actor class of :class:`EdgeHost` (async actor; place it with ``label_selector={"tier": "edge"}``).
EdgeHostActor = _LazyActorClass(EdgeHost, num_cpus=0, max_concurrency=1000, max_restarts=0)

