"""The edge side of the cloud: :class:`CloudPool`, the client of a set of cloud executors
(:data:`aerodaas.actors.cloud.executor.CloudExecutorActor`), shared by the dispatchers of one process.

Cloud transport
---------------
One Ray call per cloud task does not scale on a small machine: measured on 2 cores, 400 calls/s to an async actor
gave a p99 completion error of ~200 ms and 800/s collapsed (> 1 s). The pool therefore batches: all requests
created in one loop iteration for one executor go in one ``submit`` call, and each executor keeps one long-poll
``collect`` call per client outstanding, which returns every completion ready at that moment (so the number of
calls adapts to the load, and a completion waits at most one call round trip, a few ms). The executor's death
surfaces on that outstanding call at once (``ActorDiedError``). Each ``collect`` acknowledges the replies of the
previous one and the executor keeps a reply until acknowledged, so a call whose answer is lost on the way
(``ActorUnavailableError``: a live actor Ray could not reach for a moment) is simply repeated and loses nothing;
a ``submit`` call failing so is sent again (the executor runs a request it already has only once); new tasks go
to the other executors meanwhile, and one unreachable for ``unavailable_after_ms`` (3 s) counts as dead (a call to
an actor on a node that just died raises the same error until Ray learns of the death, which can take ten seconds
and more on a loaded machine).

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
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import itertools
import logging
import math
import os
import time
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any, Protocol, Sequence

from aerodaas.schedulers.analytics_base import AnalyticsTask, Workload

from aerodaas.schedulers.dispatch.clock import Clock
from aerodaas.schedulers.dispatch.emulation import Jitter, NetworkModel, seeded_rng
from aerodaas.schedulers.dispatch.payload import frame_from_payload
from aerodaas.schedulers.dispatch.stats import Samples

__all__ = ["CloudClient", "CloudPool"]

log = logging.getLogger(__name__)


def _temporarily_unavailable(e: BaseException) -> bool:
    """Whether ``e`` is Ray's ``ActorUnavailableError`` (the actor may be reachable again later; Ray's
    ``ray.exceptions``), as opposed to its death (``ActorDiedError``) or any other error."""
    from ray.exceptions import ActorUnavailableError  # lazy: heavy ray; only on an error

    return isinstance(e, ActorUnavailableError)


def _actor_died(e: BaseException) -> bool:
    """Whether ``e`` is Ray's ``RayActorError`` (the actor died: ``ActorDiedError`` and its kin), which the
    executor's collector sees too."""
    from ray.exceptions import ActorUnavailableError, RayActorError  # lazy: heavy ray; only on an error

    return isinstance(e, RayActorError) and not isinstance(e, ActorUnavailableError)


class CloudClient(Protocol):
    """What the pool needs of a dispatcher that sends it tasks
    (:class:`~aerodaas.schedulers.dispatch.dispatcher.AnalyticsDispatcher` is one; the pool does not import it,
    the dispatcher imports the pool): its edge id, clock and workload (task profiles by model), and three
    callbacks, run on the dispatcher's event loop."""

    edge_id: str
    clock: Clock
    workload: Workload

    def cloud_admits(self, task: AnalyticsTask, now_ms: float) -> bool:
        """Whether the dispatcher's policy still admits ``task`` to the cloud at ``now_ms`` (ms, run clock)."""

    def on_cloud_reply(self, task: AnalyticsTask, reply: dict, latency_ms: float, executor: str | None) -> None:
        """A reply (or failure, ``reply["failed"]``) for ``task`` after ``latency_ms`` (ms) from ``executor``."""

    def on_cloud_availability(self, available: bool) -> None:
        """The cloud became unavailable (no executor alive) or available again."""


@dataclass
class _InFlight:
    dispatcher: CloudClient
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
    not add to the emulated round trip; 0 makes the reply's arrival time the completion time.
    ``unavailable_after_ms``: an executor Ray cannot reach (``ActorUnavailableError``) this long in a row counts as
    dead; meanwhile new tasks go to the others when there are any. See the module docstring for the transport and
    the loss handling.
    """

    def __init__(self, executors: Sequence[Any], *, mode: str = "emulated", network: NetworkModel | None = None,
                 jitter: Jitter = Jitter("lognormal", 0.1), seed: int = 0, retry: bool = True,
                 lost_after_ms: float = 10_000.0, jpeg_quality: int = 90, client_id: str | None = None,
                 reply_lead_ms: float = 100.0, unavailable_after_ms: float = 3_000.0) -> None:
        if mode not in ("emulated", "real"):
            raise ValueError(f"mode must be 'emulated' or 'real', got {mode!r}")
        if not (reply_lead_ms >= 0 and math.isfinite(reply_lead_ms)):
            raise ValueError(f"reply_lead_ms must be a finite number >= 0, got {reply_lead_ms!r}")
        self.reply_lead_ms = float(reply_lead_ms)
        if not (unavailable_after_ms >= 0 and math.isfinite(unavailable_after_ms)):
            raise ValueError(f"unavailable_after_ms must be a finite number >= 0, got {unavailable_after_ms!r}")
        self.unavailable_after_ms = float(unavailable_after_ms)
        #: executor -> time.monotonic() of its first failed poll in a row (``ActorUnavailableError``)
        self._unavailable_since: dict[int, float] = {}
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
        self.dispatchers: list[CloudClient] = []
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
        #: the submit calls being awaited (:meth:`_submitted`): kept (asyncio holds only weak references to a task)
        #: and cancelled by :meth:`close`, which also stops any new send (``_closing``)
        self._submits: set[asyncio.Task] = set()
        self._closing = False
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
        """Stop sending and collecting, and forget this client's work on the executors that are still alive."""
        self._closing = True
        tasks = [*self._tasks, *self._submits]
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        self._tasks.clear()
        await asyncio.gather(*(self._call(i, "reset", self.client) for i in range(len(self.executors))
                               if self.alive[i]), return_exceptions=True)
        if self._encoder is not None:
            self._encoder.shutdown(wait=False)

    def attach(self, dispatcher: CloudClient) -> None:
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
                d.on_cloud_availability(True)
        return info

    @property
    def available(self) -> bool:
        return any(self.alive)

    @property
    def started(self) -> bool:
        """True once :meth:`start` bound the pool to an event loop (it is then started only once)."""
        return self._loop is not None

    def fail_in_flight(self, dispatcher: CloudClient, reason: str) -> int:
        """End every task of ``dispatcher`` still in flight on the cloud as failed with ``reason`` (its
        ``on_cloud_reply`` hears ``{"ok": False, "failed": True, "error": reason}``; a reply arriving later is
        ignored). Returns how many were failed. Call it on the pool's event loop."""
        keys = [k for k, f in self._inflight.items() if f.dispatcher is dispatcher]
        for k in keys:
            self._finish_failed(k, reason)
        return len(keys)

    def in_flight(self, dispatcher: CloudClient | None = None) -> int:
        return sum(1 for f in self._inflight.values() if dispatcher is None or f.dispatcher is dispatcher)

    def name_of(self, i: int) -> str:
        return self.infos[i].get("name") or f"#{i}"

    # ---- sending
    def _pick(self, avoid: int | None = None) -> int | None:
        """Round robin over the live executors, those Ray can reach first (an unreachable one only when it is all
        there is: its tasks then wait for it to answer or be counted dead), executor ``avoid`` only when it is the
        only one alive."""
        alive = [i for i, a in enumerate(self.alive) if a]
        alive = [i for i in alive if i != avoid] or alive
        if not alive:
            return None
        reachable = [i for i in alive if i not in self._unavailable_since] or alive
        return reachable[next(self._rr) % len(reachable)]

    def send(self, dispatcher: CloudClient, task: AnalyticsTask, admit_by_ms: float, now_ms: float) -> bool:
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
        import cv2  # lazy: heavy cv2

        frame = frame_from_payload(payload)
        ok, buf = cv2.imencode(".jpg", frame, [int(cv2.IMWRITE_JPEG_QUALITY), self.jpeg_quality])
        if not ok:
            raise ValueError("cv2.imencode failed")
        return buf.tobytes()

    def _queue(self, i: int, req: dict) -> None:
        if self._closing:  # closed: the executors forget this client (reset); nothing is sent after that
            return
        self._outbox[i].append(req)
        if not self._flush_scheduled:
            self._flush_scheduled = True
            self._loop.call_soon(self._flush)

    def _flush(self) -> None:
        self._flush_scheduled = False
        boxes, self._outbox = self._outbox, defaultdict(list)
        for i, reqs in boxes.items():
            # a request whose task went elsewhere meanwhile (its executor died: _executor_died rerouted it) or
            # ended is not sent here
            reqs = [r for r in reqs if (f := self._inflight.get(r["k"])) is not None and f.executor == i]
            if not reqs:
                continue
            if not self.alive[i]:
                for r in reqs:
                    self._reroute_or_fail(r["k"], f"cloud executor {self.name_of(i)} died before the task was sent")
                continue
            ex = self.executors[i]
            call = ex.submit.remote(self.client, reqs) if self._is_actor(ex) else ex.submit(self.client, reqs)
            t = self._loop.create_task(self._submitted(i, reqs, call))
            self._submits.add(t)
            t.add_done_callback(self._submits.discard)

    async def _submitted(self, i: int, reqs: list[dict], call: Any) -> None:
        """Wait for executor ``i`` to accept ``reqs`` (``call``: its ``submit`` call, a Ray ObjectRef or a
        coroutine). A call Ray could not deliver for certain (``ActorUnavailableError``: "may or may not have been
        executed") is sent again 0.2 s later while the requests' tasks are still in flight there; the executor
        runs a request it already has only once. The executor's death (Ray's ``RayActorError``) is left to its
        collector, which retries or fails every task in flight there (:meth:`_executor_died`); any other failure (the
        executor raised while taking the batch) is logged and the batch's tasks still in flight there are retried
        elsewhere or failed (:meth:`_reroute_or_fail`), instead of waiting for the watchdog."""
        try:
            await call
        except asyncio.CancelledError:
            raise
        except Exception as e:
            if _temporarily_unavailable(e):
                await asyncio.sleep(0.2)
                for r in reqs:
                    f = self._inflight.get(r["k"])
                    if f is not None and f.executor == i:
                        self._queue(i, r)
                return
            if _actor_died(e):
                return
            why = f"cloud executor {self.name_of(i)} did not take the task: {type(e).__name__}: " + \
                (str(e).splitlines()[0] if str(e) else "")
            log.warning("%s (a batch of %d)", why, len(reqs))
            for r in reqs:
                f = self._inflight.get(r["k"])
                if f is not None and f.executor == i:
                    self._reroute_or_fail(r["k"], why, avoid=i)

    # ---- replies
    async def _collector(self, i: int) -> None:
        """Executor ``i``'s long poll. Each call acknowledges the replies of the previous one (the executor keeps a
        reply until then: an answer lost on the way comes again). A call failing with Ray's
        ``ActorUnavailableError`` (the actor may come back: a broken connection, an unresponsive process; it is also
        what a call to an actor on a node that just died raises until Ray learns of the death) is repeated every
        0.2 s; the executor counts as dead after ``unavailable_after_ms`` of that, or at once on any other error
        (``ActorDiedError``)."""
        ack: list[int] = []
        while self.alive[i]:
            try:
                replies = await self._call(i, "collect", self.client, 5.0, ack)
            except asyncio.CancelledError:
                raise
            except Exception as e:
                now = time.monotonic()
                since = self._unavailable_since.get(i)
                if _temporarily_unavailable(e) and (since is None
                                                    or now - since < self.unavailable_after_ms / 1000.0):
                    if since is None:
                        self._unavailable_since[i] = now
                        log.warning("cloud executor %s unavailable, polling it again: %s", self.name_of(i),
                                    str(e).splitlines()[0] if str(e) else type(e).__name__)
                    await asyncio.sleep(0.2)
                    continue
                self._unavailable_since.pop(i, None)
                self._executor_died(i, e)
                return
            self._unavailable_since.pop(i, None)
            ack = [r["k"] for r in replies]
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
        f.dispatcher.on_cloud_reply(f.task, r, latency, self.name_of(i))

    def _finish_failed(self, key: int, reason: str) -> None:
        f = self._inflight.pop(key, None)
        if f is None:
            return
        now = f.dispatcher.clock.now_ms()
        f.dispatcher.on_cloud_reply(f.task, {"ok": False, "error": reason, "failed": True}, now - f.sent_ms, None)

    def _reroute_or_fail(self, key: int, why: str, avoid: int | None = None) -> str:
        """Retry ``key`` on a surviving executor if allowed and the policy still admits it (executor ``avoid`` only
        when no other is alive); else FAILED."""
        f = self._inflight.get(key)
        if f is None:
            return "gone"
        d = f.dispatcher
        now = d.clock.now_ms()
        if self.retry and not f.retried and self.available and d.cloud_admits(f.task, now):
            j = self._pick(avoid)
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
                d.on_cloud_availability(False)
        for k in keys:
            outcome = self._reroute_or_fail(k, f"cloud executor {ev['name']} (node {node}) died at "
                                               f"{now_ms / 1000:.1f} s while the task was in flight")
            if outcome in ("retried", "failed"):
                ev[outcome] += 1
        self.events.append(ev)
        log.warning("cloud executor %s on node %s died at %.1f s: %d in flight (%d retried, %d failed): %s",
                    ev["name"], node, ev["at_s"], ev["in_flight"], ev["retried"], ev["failed"], ev["error"])

    async def _watchdog(self) -> None:
        while True:
            await asyncio.sleep(0.5)
            for k, f in list(self._inflight.items()):
                if f.dispatcher.clock.now_ms() > max(f.task.deadline_ms, f.sent_ms) + self.lost_after_ms:
                    self._finish_failed(k, f"no reply from the cloud {self.lost_after_ms / 1000:.0f} s after the "
                                           "deadline")

    def report(self) -> dict:
        """The pool's state as JSON-ready values: ``executors`` (per executor ``name``, ``node_id``, ``labels``,
        ``alive``: not counted dead, ``reachable``: alive and its last poll answered), ``losses`` (one event per
        executor death: ``executor``, ``name``, ``node_id``, ``at_s`` on the run's clock, ``error``, ``in_flight``,
        ``retried``, ``failed``), ``sent``/``retried``/``in_flight`` task counts, ``mode``, ``network``, ``jitter``,
        ``reply_lead_ms`` and ``reply_margin_ms`` (how early replies arrived, ms)."""
        return {"executors": [{"name": self.name_of(i), "node_id": self.infos[i].get("node_id"),
                               "labels": self.infos[i].get("labels", {}), "alive": self.alive[i],
                               "reachable": self.alive[i] and i not in self._unavailable_since}
                              for i in range(len(self.executors))],
                "losses": list(self.events), "sent": self.sent, "retried": self.retried,
                "in_flight": len(self._inflight), "mode": self.mode, "network": self.network.describe(),
                "jitter": str(self.jitter), "reply_lead_ms": self.reply_lead_ms,
                "reply_margin_ms": self.reply_margin.summary()}
