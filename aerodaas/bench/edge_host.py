"""The benchmark's edge host: :class:`EdgeHost` (Ray actor :data:`EdgeHostActor`, ``label_selector={"tier":
"edge"}``) hosts several :class:`~aerodaas.schedulers.dispatch.dispatcher.AnalyticsDispatcher` s (one per emulated
edge device) and one shared :class:`~aerodaas.schedulers.dispatch.cloud_pool.CloudPool` on one asyncio loop;
``aerodaas bench schedulers`` replays arrival traces with it. Benchmark-only: production code never imports it.
"""
from __future__ import annotations

import asyncio
import gc
import itertools
import time
from typing import Any, Mapping, Sequence

from aerodaas.actors.host.remote import LazyActorClass, where
from aerodaas.schedulers import single_machine_jit
from aerodaas.schedulers.analytics_base import Workload, make_analytics_scheduler
from aerodaas.schedulers.dispatch.clock import Clock, set_result_if_pending
from aerodaas.schedulers.dispatch.cloud_pool import CloudPool
from aerodaas.schedulers.dispatch.dispatcher import AnalyticsDispatcher
from aerodaas.schedulers.dispatch.edge_executors import EmulatedEdgeExecutor, OnnxEdgeExecutor
from aerodaas.schedulers.dispatch.emulation import Jitter, NetworkModel

__all__ = ["EdgeHost", "EdgeHostActor"]


class EdgeHost:
    """Hosts several :class:`AnalyticsDispatcher` s (one per edge device) and one shared :class:`CloudPool` on one
    asyncio loop: a Ray async actor (:data:`EdgeHostActor`, place it with ``label_selector={"tier": "edge"}``).

    Hosting many emulated edge devices in one process keeps memory and CPU sane (the tasks are timers). The
    benchmark configures a run (:meth:`configure`), replays a seeded arrival trace (:meth:`run_trace`) and reads
    the per-device reports. :meth:`submit` is the live entry point (a frame path in another actor).
    """

    def __init__(self, name: str = "edge-host") -> None:
        self.name = name
        # load LAPLAN's compiled planner now (seconds on first use): inside configure() it would overrun the run's
        # lead time (start_epoch), and a deployment's dispatcher actor likewise loads it when it starts
        single_machine_jit.warm_up()
        self.dispatchers: dict[str, AnalyticsDispatcher] = {}
        self.pool: CloudPool | None = None
        self.clock: Clock | None = None

    async def info(self) -> dict:
        """Where this host runs: ``name``, ``pid``, ``node_id``, node ``labels``, and whether LAPLAN's planner runs
        compiled here (``laplan_planner``: :func:`aerodaas.schedulers.single_machine_jit.status`)."""
        return {"name": self.name, **where(), "laplan_planner": single_machine_jit.status()}

    async def configure(self, *, scheduler: str, workload: Workload, edge_ids: Sequence[str],
                        cloud_executors: Sequence[Any] = (), start_epoch: float | None = None,
                        mode: str = "emulated", edge_jitter: str = "lognormal:0.05",
                        cloud_jitter: str = "lognormal:0.1", network: Sequence[str] | str | None = None,
                        seed: int = 0, retry: bool = True, scheduler_kwargs: Mapping[str, Any] | None = None,
                        detector_for: Mapping[str, str] | str = "yolox_nano", reply_lead_ms: float = 100.0) -> dict:
        """Create one dispatcher with a fresh ``scheduler`` policy per edge id, sharing a new cloud pool over
        ``cloud_executors`` (none: edge-only). ``start_epoch``: the run's time origin (epoch s), shared by every
        host of a run. Raises ValueError (unknown scheduler, bad specs) before anything starts."""
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
        as ``arrival_lateness``; ``cpu_s`` is this host process's CPU time over the replay (to tell a host that
        needs more CPU than the run's wall time from one that got too little of a loaded machine)."""
        loop = asyncio.get_running_loop()
        cpu0 = time.process_time()
        gc_pauses: list[float] = []   # cyclic-GC passes in this process during the replay (ms, wall)
        gc_t0 = [0.0]

        def on_gc(phase: str, info: dict) -> None:
            if phase == "start":
                gc_t0[0] = time.perf_counter()
            else:
                gc_pauses.append((time.perf_counter() - gc_t0[0]) * 1e3)

        gc.callbacks.append(on_gc)
        for group_t, rows in itertools.groupby(trace, key=lambda r: r[0]):
            delay = self.clock.loop_time(loop, group_t) - loop.time()
            if delay > 0:
                fut = loop.create_future()
                loop.call_at(loop.time() + delay, set_result_if_pending, fut, None)
                await fut
            for t_ms, edge_id, drone, model in rows:
                self.dispatchers[edge_id].submit(drone, model, None, t_ms)
        reports = await asyncio.gather(*(d.finish(drain_timeout_s) for d in self.dispatchers.values()))
        gc.callbacks.remove(on_gc)
        if samples:
            reports = [d.report(samples=True) for d in self.dispatchers.values()]
        out = {"edges": reports, "cloud": self.pool.report() if self.pool else None,
               "cloud_rtt_error_ms": self.pool.rtt_error.values if self.pool else [],
               "cloud_reply_margin_ms": self.pool.reply_margin.values if self.pool else [],
               "cpu_s": time.process_time() - cpu0,  # this host process's CPU over the replay and drain
               "gc_pauses_ms": {"n": len(gc_pauses), "total": sum(gc_pauses), "max": max(gc_pauses, default=0.0)}}
        return out

    async def close(self) -> None:
        """Finish any dispatcher still running and release the cloud pool."""
        for d in self.dispatchers.values():
            if d.running:
                await d.finish(0.0)
        self.dispatchers = {}
        if self.pool is not None:
            await self.pool.close()
            self.pool = None


#: Ray actor class of :class:`EdgeHost` (async actor; place it with ``label_selector={"tier": "edge"}``).
EdgeHostActor = LazyActorClass(EdgeHost, num_cpus=0, max_concurrency=1000, max_restarts=0)
