"""The cloud side of analytics scheduling: :class:`CloudExecutor`, an asyncio object wrapped as the Ray actor
:data:`CloudExecutorActor` and placed with ``label_selector={"tier": "cloud"}`` (:func:`start_cloud_executors`).

Emulated: it holds ``cloud_ms`` x jitter plus the network latency drawn by the edge's
:class:`~aerodaas.schedulers.dispatch.emulation.NetworkModel`; real: it decodes the JPEG and runs the ONNX model
(or an application's analytics). Lambda-like: it runs any number of tasks at once (real mode: ``threads``
detector threads). Its client is :class:`aerodaas.schedulers.dispatch.cloud_pool.CloudPool` (batched transport,
replies sent ahead of their due time in emulated mode: see that module's docstring).

The cloud re-check: a request carries an *admit-by* time (epoch s) computed on the edge from the policy's
``cloud_admit`` (see :mod:`aerodaas.schedulers.dispatch.dispatcher`). The executor compares it with its clock when
the request arrives, before the emulated uplink, and in real mode again when a detector thread picks the task up;
a refused task is replied ``ok=False`` with an error starting ``cloud re-check``.
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import threading
import time
from collections import OrderedDict, defaultdict
from typing import Any, Mapping, Sequence

from aerodaas.schedulers.dispatch.banks import AnalyticsBank, DetectorBank
from aerodaas.schedulers.dispatch.payload import frame_from_payload

from aerodaas.actors.host.remote import LazyActorClass, where

__all__ = ["CloudExecutor", "CloudExecutorActor", "cloud_selector", "start_cloud_executors"]

#: how long (s) an executor remembers a client's request key, so that a batch sent again runs once: a client sends
#: a batch again only while its tasks are in flight there (0.2 s after a call Ray could not deliver; a task is given up
#: on by its client 10 s after its deadline), so the keys of a client that stopped are forgotten after this
_ACCEPTED_FOR_S = 120.0
#: at most this many keys per client (the oldest forgotten first): the memory bound of a fast client (about 8 MB)
_ACCEPTED_KEPT = 65_536


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
    model name -> an application's :class:`~aerodaas.analytics.core.Analytics`, run instead of the ONNX detectors (a copy
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
        self._bank = (AnalyticsBank(analytics) if analytics else DetectorBank(detector_for, detector_kwargs)) \
            if mode == "real" else None
        self._pool = concurrent.futures.ThreadPoolExecutor(int(threads), thread_name_prefix="cloud-onnx") \
            if mode == "real" else None
        if self._pool is not None:
            self._prepare_threads(int(threads))
        self._ready: dict[str, list[dict]] = defaultdict(list)
        self._unacked: dict[str, dict[int, dict]] = defaultdict(dict)  # client -> key -> reply handed out
        #: client -> key -> arrival (time.monotonic()) of its requests of the last _ACCEPTED_FOR_S seconds (at most
        #: _ACCEPTED_KEPT): a request sent again is not run twice
        self._accepted: dict[str, OrderedDict[int, float]] = defaultdict(OrderedDict)
        self._events: dict[str, asyncio.Event] = {}
        self._handles: dict[str, set] = defaultdict(set)
        self.executed = 0
        self.refused = 0
        self._loop: asyncio.AbstractEventLoop | None = None

    def _prepare_threads(self, threads: int) -> None:
        """Set up the models on each of the ``threads`` pool threads before the first task (the bank keeps one
        instance per thread, built on first use: otherwise the run's first frame on each thread waits for an ONNX
        session to open; the first task of a cloud executor once took 6 s, beside two CPU burners). A barrier keeps
        the ``threads`` jobs on distinct threads. Raises the first error of a set-up (the executor then never
        starts, and :func:`start_cloud_executors` raises it)."""
        barrier = threading.Barrier(threads)

        def one() -> None:
            try:
                self._bank.prepare()
            except BaseException:
                barrier.abort()
                raise
            barrier.wait()

        errors = []
        for fut in [self._pool.submit(one) for _ in range(threads)]:
            try:
                fut.result()
            except threading.BrokenBarrierError as e:
                errors.append(e)
            except Exception as e:  # the set-up's own error comes first
                errors.insert(0, e)
        if errors:
            self._pool.shutdown(wait=False)
            raise errors[0]

    # ---- API
    async def info(self) -> dict:
        """Where this executor runs: ``name``, ``mode``, ``pid``, and (inside Ray) ``node_id`` and ``labels``."""
        return {"name": self.name, "mode": self.mode, **where()}

    async def submit(self, client: str, reqs: list[dict]) -> int:
        """Accept a batch of requests from ``client``; returns how many were new. A request whose key (``k``) the
        client sent within :data:`_ACCEPTED_FOR_S` (its latest :data:`_ACCEPTED_KEPT`) is ignored: the client sends a
        batch again when Ray could not tell whether the first call arrived (``ActorUnavailableError``: "may or may
        not have been executed"). A key is remembered once its request was taken (a request that raised is not)."""
        loop = self._loop = asyncio.get_running_loop()
        wall, lt, now = time.time(), loop.time(), time.monotonic()
        self._forget_accepted(now - _ACCEPTED_FOR_S)
        accepted = self._accepted[client]
        new = 0
        for req in reqs:  # arrival: the re-check comes before the emulated uplink (see the module docstring)
            if req["k"] in accepted:
                continue
            self._arrive(client, req, loop, wall, lt)
            accepted[req["k"]] = now
            if len(accepted) > _ACCEPTED_KEPT:
                accepted.popitem(last=False)
            new += 1
        return new

    def _forget_accepted(self, before: float) -> None:
        """Forget the request keys that arrived before monotonic time ``before``, and the clients left with none."""
        for client in list(self._accepted):
            keys = self._accepted[client]
            while keys and next(iter(keys.values())) < before:
                keys.popitem(last=False)
            if not keys:
                del self._accepted[client]

    async def collect(self, client: str, max_wait_s: float = 5.0,
                      ack: Sequence[int] | None = None) -> list[dict]:
        """Long poll: every reply ready for ``client``, as soon as there is at least one (or ``[]`` after
        ``max_wait_s`` seconds). ``ack``: the keys (``k``) of the replies the client received from its previous
        call. With it, a reply stays with the executor until acknowledged and every call returns all unacknowledged
        ones, so the answer of a call lost on the way back (Ray's ``ActorUnavailableError``: "the task may or may
        not have been executed") comes again with the next call; the client ignores a key it already has. Without
        it (None), each reply is handed out once."""
        unacked = self._unacked[client]
        for k in ack or ():
            unacked.pop(k, None)
        if not self._ready[client] and not (ack is not None and unacked):
            ev = self._event(client)
            ev.clear()
            try:
                await asyncio.wait_for(ev.wait(), max_wait_s)
            except asyncio.TimeoutError:
                return []
        out, self._ready[client] = self._ready[client], []
        if ack is None:
            return out
        for r in out:
            unacked[r["k"]] = r
        return list(unacked.values())

    async def reset(self, client: str | None = None) -> None:
        """Forget ``client``'s (or every client's) pending work and replies."""
        for c in ([client] if client is not None else {*self._handles, *self._ready, *self._unacked}):
            for h in self._handles.pop(c, ()):
                h.cancel()
            self._ready.pop(c, None)
            self._unacked.pop(c, None)
            self._accepted.pop(c, None)

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
        out = self._bank.run(req["model"], frame_from_payload(req["jpeg"]), req.get("meta"))
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


#: Ray actor class of :class:`CloudExecutor` (an async actor; place it with ``label_selector={"tier": "cloud"}``).
CloudExecutorActor = LazyActorClass(CloudExecutor, num_cpus=0, max_concurrency=1000, max_restarts=0)


def cloud_selector(has_cloud_nodes: bool) -> dict[str, str]:
    """``{"tier": "cloud"}``, or ``{"tier": "in(edge,cloud)"}`` on a cluster without cloud nodes (local mode)."""
    return {"tier": "cloud"} if has_cloud_nodes else {"tier": "in(edge,cloud)"}


def start_cloud_executors(n: int, mode: str = "emulated", *, selector: Mapping[str, str] | None = None,
                          name_prefix: str = "cloud", threads: int = 2, spread: bool = True,
                          detector_for: Mapping[str, str] | str = "yolox_nano",
                          detector_kwargs: Mapping[str, Any] | None = None,
                          analytics: Mapping[str, Any] | None = None, ray_name_prefix: str | None = None) -> list:
    """Start ``n`` :data:`CloudExecutorActor` s on tier=cloud nodes (``selector`` defaults to
    :func:`cloud_selector` for the current cluster), spread over the nodes that match; ``ray_name_prefix``: name
    them ``<prefix><i>`` in Ray (``ray list actors``). Returns the handles once each has answered
    :meth:`CloudExecutor.info`. Raises ValueError for ``n < 1``."""
    import ray  # lazy: heavy ray

    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if selector is None:
        selector = cloud_selector(any(x.get("Alive") and x.get("Labels", {}).get("tier") == "cloud"
                                      for x in ray.nodes()))
    opts: dict[str, Any] = {"label_selector": dict(selector)}
    if spread:
        opts["scheduling_strategy"] = "SPREAD"
    handles = [CloudExecutorActor.options(**opts, **({"name": f"{ray_name_prefix}{i}"} if ray_name_prefix else {}))
               .remote(f"{name_prefix}{i}", mode, threads, detector_for, detector_kwargs, analytics)
               for i in range(n)]
    ray.get([h.info.remote() for h in handles])
    return handles
