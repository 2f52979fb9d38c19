"""``aerodaas bench schedulers`` (its command line: :mod:`aerodaas.bench.schedulers_cli`): analytics schedulers on
seeded drone-fleet traces, on real Ray actors (or, with ``--harness``, on the deterministic policy harness:
:mod:`aerodaas.bench.sweep`). Every figure is reported as mean ±
95 % CI over ``--seeds`` (:mod:`aerodaas.bench.schedulers_report`); the per-seed runs are kept in ``runs``.

Every scheduler (all registered ones by default) runs the SAME arrival trace, in emulated mode, with wall-clock
time, on a local multi-node Ray cluster (one ``tier=edge`` node, ``--cloud-nodes`` ``tier=cloud`` nodes; see
:mod:`aerodaas.clusters.local`) or on the cluster at ``--address``:

* edge devices: ``ceil(drones / drones_per_edge)`` emulated edge accelerators, each an
  :class:`~aerodaas.schedulers.dispatch.dispatcher.AnalyticsDispatcher` with its own policy instance, hosted by a few
  :class:`~aerodaas.bench.edge_host.EdgeHost` actors on the edge node (many devices per process: the tasks are timers);
* cloud: :class:`~aerodaas.actors.cloud.executor.CloudExecutor` actors on the cloud nodes (Lambda-like, unbounded
  concurrency), holding ``cloud_ms`` x jitter plus the ``--network-variability`` latency.

Arrival process (see ``arrival_process`` in the JSON): the Ocularone scheduler creates, for every batch a drone
sends, one task per model active under the load, in a shuffled order (``TaskCreation.java``), with the deadline
counted from the batch's arrival; the profiled times are for 1-frame batches (``DNNPerfModel`` is keyed by the
frame count, and only count 1 is configured), and the drone emulator sends one batch per second
(``batch_length: 1`` s in ``conf/config.yaml``; ``mock_edge.py`` paces clients at one request a second). Here each
drone sends one frame every ``1/fps`` s (default 1 fps) from a seeded random phase, and each frame yields one
task per active model, in a seeded shuffled order, all at the frame's arrival time. The paper emulates "over 80
drones supporting over 25 VIPs" with several drones linked to each Jetson Nano edge; we read that as about 3
drones per edge (27 edges of 3 drones = 81 drones for 27 VIPs) and default to ``--drones-per-edge 3`` (the
text of the paper's experimental setup was not available to check the exact figure).

Timing faithfulness is measured and reported (``emulation`` in the JSON): how late the replay delivered arrivals,
actual vs intended edge hold, actual vs intended cloud round trip, how late policy polls fired.
"""
from __future__ import annotations

import functools
import itertools
import math
import os
import random
import sys
import time
from collections import Counter
from dataclasses import asdict
from pathlib import Path
from typing import Sequence

import ray

from aerodaas.actors.cloud.executor import start_cloud_executors
from aerodaas.bench.edge_host import EdgeHostActor
from aerodaas.bench.machine import machine_info
from aerodaas.bench.options import DEFAULT_DRONES_PER_EDGE, DEFAULT_FPS, EMULATION_BOUND_MS, LOADS
from aerodaas.bench.schedulers_report import _emulation_p99, summarize_runs
from aerodaas.bench.sweep import scenario_specs
from aerodaas.bench.workload import default_workload_path, edge_layout, make_trace
from aerodaas.clusters.local import LocalCluster
from aerodaas.schedulers.analytics_base import (Workload, analytics_scheduler_names, filter_options, iter_schedulers,
                                                make_analytics_scheduler)
from aerodaas.schedulers.dispatch.emulation import Jitter, NetworkModel
from aerodaas.schedulers.dispatch.stats import Samples

#: how often a run configures its edge hosts, the lead time doubling each time, before it gives up (RuntimeError)
LEAD_TRIES = 3


# ---------------------------------------------------------------------------------------------- cluster
class _Cluster:
    """The benchmark's Ray cluster: a LocalCluster it started, or the cluster at ``address``."""

    def __init__(self, address: str | None, cloud_nodes: int) -> None:
        self.local = None
        if address:
            if not ray.is_initialized():
                ray.init(address=address, include_dashboard=False, logging_level="warning")
        else:
            if ray.is_initialized():
                ray.shutdown()

            self.local = LocalCluster(cloud_nodes=cloud_nodes, edge_cpus=2, cloud_cpus=2, worker_niceness=0)

    def nodes(self) -> list[dict]:
        return [{"node_id": n["NodeID"], "labels": {k: v for k, v in n.get("Labels", {}).items()
                                                     if not k.startswith("ray.io/")}}
                for n in ray.nodes() if n.get("Alive")]

    def close(self) -> None:
        if self.local is not None:
            self.local.shutdown()


def _pooled(values: list[float]) -> dict:
    return Samples.summarize(values)


# ---------------------------------------------------------------------------------------------- one run
def _merge(name: str, load: str, drones: int, n_edges: int, per_edge: int, host_outs: list[dict], wall_s: float
           ) -> dict:
    edges = [r for out in host_outs for r in out["edges"]]
    c = Counter()
    states, tiers, drops, reasons = Counter(), Counter(), Counter(), Counter()
    ubm, tbm, obm, counters = Counter(), Counter(), Counter(), Counter()
    cpu_by_call: Counter = Counter()  # policy call name -> CPU s, summed over the edges
    utility = cloud_cost = edge_cost = 0.0
    dec, hold, late, poll = [], [], [], []
    for r in edges:
        c["submitted"] += r["submitted"]
        c["pending"] += r["pending"]
        c["policy_errors"] += r["accounting"]["policy_errors"]
        states.update(r["states"])
        tiers.update(r["tiers"])
        drops.update(r["drops"])
        reasons.update(r["drop_reasons"])
        ubm.update(r["utility_by_model"])
        tbm.update(r["tasks_by_model"])
        obm.update(r["on_time_by_model"])
        utility += r["utility"]
        cloud_cost += r["cloud_cost"]
        edge_cost += r["edge_cost"]
        for k, v in r.get("counters", {}).items():
            if k == "cloud_peak_concurrency":
                c["peak"] = max(c["peak"], v)
            else:
                counters[k] += v
        for k, v in r.get("policy_cpu_s", {}).items():
            cpu_by_call[k] += v
        s = r.get("samples", {})
        dec += s.get("decision_us", [])
        hold += s.get("edge_hold_error_ms", [])
        late += s.get("arrival_lateness_ms", [])
        poll += s.get("poll_lateness_ms", [])
    rtt = [v for out in host_outs for v in out.get("cloud_rtt_error_ms", [])]
    margin = [v for out in host_outs for v in out.get("cloud_reply_margin_ms", [])]
    utils = [r["edge_utilisation"] for r in edges]
    losses = [ev for out in host_outs if out.get("cloud") for ev in out["cloud"]["losses"]]
    total = c["submitted"]
    return {
        "scheduler": name, "load": load, "drones": drones, "edges": n_edges, "drones_per_edge": per_edge,
        "tasks": total, "on_time_rate": states["done_on_time"] / total if total else 0.0,
        "utility": utility, "utility_by_model": dict(ubm), "tasks_by_model": dict(tbm),
        "on_time_by_model": dict(obm), "cloud_cost": cloud_cost, "edge_cost": edge_cost,
        "drops": dict(drops), "drop_reasons": dict(reasons.most_common()), "states": dict(states), "tiers": dict(tiers),
        "edge_utilisation": sum(utils) / len(utils) if utils else 0.0,
        "edge_utilisation_min_max": [min(utils, default=0.0), max(utils, default=0.0)],
        "decision_us": _pooled(dec),
        "timing_ms": {"arrival_lateness": _pooled(late), "edge_hold_error": _pooled(hold),
                      "cloud_rtt_error": _pooled(rtt), "poll_lateness": _pooled(poll),
                      "cloud_reply_margin": _pooled(margin)},
        "accounting": {"submitted": total, "terminal": sum(states.values()), "pending": c["pending"],
                       "policy_errors": c["policy_errors"]},
        "counters": {**counters, "cloud_peak_concurrency_per_edge": c["peak"]},
        "cloud_losses": losses, "wall_s": wall_s,
        # CPU of the edge host processes over the replay: where the emulation's time goes (policy decisions plus the
        # dispatchers' timers and cloud calls); per host, beside the policy's own share (sum of decision times)
        "host_cpu_s": [round(out.get("cpu_s", 0.0), 3) for out in host_outs],
        "host_gc_pauses_ms": [out.get("gc_pauses_ms") for out in host_outs],
        "policy_wall_s": round(sum(dec) / 1e6, 3) if dec else 0.0,
        # the policies' own CPU (thread time of their calls), by call: what a faster policy would save
        "policy_cpu_s": {k: round(v, 3) for k, v in sorted(cpu_by_call.items())},
    }


def _run_one(hosts, host_edges: list[list[str]], cloud, name: str, workload, trace_by_host, *, seed: int,
             edge_jitter: str, cloud_jitter: str, network: Sequence[str] | None, drain_s: float,
             reply_lead_ms: float, options: dict | None = None) -> list[dict]:
    t = time.time()
    # lead time for configure(): each host builds its dispatchers and loads the compiled planner before the run's
    # time origin; a loaded machine can overrun it (9 hosts at load ~40 overran 0.5 s), so an overrun configures
    # every host again (configure() closes what it had) with twice the lead, at most LEAD_TRIES times
    lead_s = 2.0 + 0.05 * sum(len(e) for e in host_edges) / max(1, len(hosts))
    for _ in range(LEAD_TRIES):
        start_epoch = time.time() + lead_s
        ray.get([h.configure.remote(scheduler=name, workload=workload, edge_ids=edges, cloud_executors=cloud,
                                    start_epoch=start_epoch, edge_jitter=edge_jitter, cloud_jitter=cloud_jitter,
                                    network=network, seed=seed, reply_lead_ms=reply_lead_ms,
                                    scheduler_kwargs=options or None)
                for h, edges in zip(hosts, host_edges)])
        if time.time() <= start_epoch:
            break
        lead_s *= 2.0
    else:
        raise RuntimeError(f"configuring the edge hosts took longer than the run's lead time {LEAD_TRIES} times "
                           f"(the last lead: {lead_s / 2.0:.1f} s)")
    outs = ray.get([h.run_trace.remote(tr, drain_s) for h, tr in zip(hosts, trace_by_host)])
    ray.get([h.close.remote() for h in hosts])
    return outs + [{"wall_s": time.time() - t}]


def _checked(schedulers, loads, repeat, cloud_nodes, reply_lead_ms, seeds, edge_jitter, cloud_jitter, network,
             cloud_sigmas, scenarios, duration_s, workload_path, options) -> tuple:
    """:func:`run_schedulers`'s parameters checked before Ray starts (ValueError naming the field): the scheduler
    names, the (sigma, cloud jitter) pairs, the scenarios and their network specs, the workload's path, the
    workloads by load and each scheduler's options (every scheduler built once with them)."""
    known = analytics_scheduler_names()
    names = list(schedulers) if schedulers else known
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ValueError(f"schedulers: unknown {unknown}; registered: {known}")
    bad = [ld for ld in loads if ld not in LOADS]
    if bad:
        raise ValueError(f"load: unknown {bad}; choose from {list(LOADS)}")
    if repeat < 1:
        raise ValueError(f"repeat must be >= 1, got {repeat}")
    if cloud_nodes < 0:
        raise ValueError(f"cloud_nodes must be >= 0, got {cloud_nodes}")
    if not (reply_lead_ms >= 0 and math.isfinite(reply_lead_ms)):
        raise ValueError(f"cloud reply lead must be a finite number of ms >= 0, got {reply_lead_ms}")
    if seeds < 1:
        raise ValueError(f"seeds must be >= 1, got {seeds}")
    Jitter.parse(edge_jitter), Jitter.parse(cloud_jitter), NetworkModel.parse(network)  # validate early
    jitters = [(None, cloud_jitter)] if not cloud_sigmas else [(float(x), str(Jitter("lognormal", float(x))))
                                                               for x in cloud_sigmas]
    scen = list(scenarios or ["none"])
    nets = {sc: list(network or []) + scenario_specs(sc, duration_s) for sc in scen}
    wpath = Path(workload_path) if workload_path else default_workload_path()
    if not wpath.is_file():
        raise ValueError(f"workload file not found: {wpath} (set AERODAAS_DATA_DIR or pass workload_path)")
    workloads = {ld: Workload.from_file(wpath, ld) for ld in loads}

    opts = {n: filter_options(n, options or {}) for n in names}
    for n in names:  # a bad option value fails here, before Ray
        make_analytics_scheduler(n, workloads[loads[0]], **opts[n])
    return names, jitters, scen, nets, wpath, workloads, opts


def _config(names, loads, drones, drones_per_edge, n_edges, fps, duration_s, repeat, trace_spec, edge_jitter,
            cloud_jitter, network, seed, cloud_nodes, address, n_hosts, n_cloud, wpath, reply_lead_ms, jitters, scen,
            options, emulation_bound_ms, drain_s) -> dict:
    """The runtime result's ``config``: every option that shaped it."""
    return {"schedulers": names, "loads": list(loads), "drones": drones, "drones_per_edge": drones_per_edge,
            "edges": n_edges, "fps": fps, "duration_s": duration_s, "repeat": repeat,
            "trace": asdict(trace_spec) if trace_spec is not None else None,
            # the jitter the measured runs used: a --cloud-sigma sweep replaces it (the CLI refuses the two together)
            "edge_jitter": edge_jitter,
            "cloud_jitter": cloud_jitter if jitters[0][0] is None else "lognormal:<cloud_sigma>",
            "network_variability": list(network or []), "network": NetworkModel.parse(network, seed).describe(),
            "cloud_nodes": cloud_nodes if not address else None, "address": address,
            "edge_hosts": n_hosts, "cloud_executors": n_cloud, "workload": str(wpath), "mode": "emulated",
            "cloud_reply_lead_ms": reply_lead_ms, "worker_niceness": 0 if not address else None,
            "cloud_sigma": [j[0] for j in jitters], "scenarios": scen, "options": dict(options or {}),
            "emulation_bound_ms": emulation_bound_ms, "drain_s": drain_s,
            "emulation_bound_why": "a run is valid only if its worst timing error p99 (arrival, edge hold, cloud "
                                   "round trip, poll) stays within this bound, a sixth of the smallest "
                                   "just-in-time margin (60 ms)"}


def _arrival_process(trace_spec, fps: float, drones_per_edge: int) -> dict:
    """The runtime result's ``arrival_process``: the per-drone process and where its rules come from."""
    return {
        "per_drone": f"one frame every {1000.0 / fps:g} ms from a seeded random phase" if trace_spec is None
        or trace_spec.kind == "periodic" else f"{trace_spec.label()} around a {1000.0 / fps:g} ms frame gap",
        "per_frame": "one task per active model, seeded shuffled order, same arrival time",
        "drones_per_edge": drones_per_edge,
        "source": "dream-lab/ocularone-scheduler: TaskCreation.java (one task per model per batch, shuffled), "
                  "DNNPerfModel keyed by frame count 1, conf/config.yaml batch_length 1 s; paper: >80 drones, "
                  ">25 VIPs, several drones per Jetson Nano edge (arXiv 2412.20860)"}


def _start_actors(nodes: list[dict], address: str | None, cloud_executors: int | None, n_hosts: int) -> tuple:
    """The edge host actors (on the ``tier=edge`` node) and the cloud executors (one per cloud node unless
    ``cloud_executors``). Raises ValueError when no node is labelled ``tier=edge``."""
    if not any(n["labels"].get("tier") == "edge" for n in nodes):
        raise ValueError(f"the cluster at {address!r} has no node labelled tier=edge (start the edge node with "
                         "`ray start --labels tier=edge`, see docs/clusters.md)")
    n_cloud_nodes = sum(1 for n in nodes if n["labels"].get("tier") == "cloud")
    cloud = start_cloud_executors(cloud_executors or max(1, n_cloud_nodes)) if (n_cloud_nodes or address) else []
    hosts = [EdgeHostActor.options(label_selector={"tier": "edge"}).remote(f"edge-host{i}") for i in range(n_hosts)]
    return hosts, cloud


def _kill(ray, actors) -> None:
    """Kill the benchmark's actors (on a shared cluster, --address, leave nothing behind)."""
    for actor in actors:
        try:
            ray.kill(actor)
        except Exception:
            pass


def _measure(hosts, host_edges, cloud, name: str, w, by_host, k: int, say, *, shape: tuple, **run_kw) -> dict:
    """Repeat ``k`` of scheduler ``name`` on the hosts (:func:`_run_one` with ``run_kw``), merged into one result
    (:func:`_merge`; ``shape`` = (load, drones, edges, drones per edge)) and reported through ``say``."""
    load, drones, n_edges, drones_per_edge = shape
    outs = _run_one(hosts, host_edges, cloud, name, w, by_host, **run_kw)
    wall = outs.pop()["wall_s"]
    r = _merge(name, load, drones, n_edges, drones_per_edge, outs, wall)
    say(f"{load} {name} #{k + 1}: on-time {100 * r['on_time_rate']:.1f}% utility {r['utility']:.0f} "
        f"cloud cost {r['cloud_cost']:.0f} decision p50/p99 {r['decision_us']['p50']:.1f}/"
        f"{r['decision_us']['p99']:.1f} us; emulation error p99 {_emulation_p99(r):.1f} ms "
        f"({wall:.0f} s; edge hosts' CPU {sum(r['host_cpu_s']):.1f} s, max per host "
        f"{max(r['host_cpu_s'], default=0):.1f} s; load average {os.getloadavg()[0]:.1f})")
    return r


def _host_edges(edge_hosts: int | None, n_edges: int) -> list[list[str]]:
    """The edge ids each edge host actor runs: ``edge_hosts`` hosts (default one per core and one more: on 2 cores,
    80 drones with LAPLAN (2026-11-24, seed 2) gave an emulation p99 of 5.1 ms with 2 hosts, 4.8-5.5 ms with 3, 7.2
    with 4, 6.8-13.3 with 5 and 8.6 with 7; each host process brings Ray's own threads, fewer hosts queue more edges
    behind each decision), at most one per edge, the edges dealt round-robin."""
    n_hosts = max(1, min(edge_hosts or (os.cpu_count() or 2) + 1, n_edges))
    edge_ids = [f"edge{e:02d}" for e in range(n_edges)]
    return [edge_ids[i::n_hosts] for i in range(n_hosts)]


def _say(progress: bool, msg: str) -> None:
    if progress:
        print(f"[bench schedulers] {msg}", file=sys.stderr, flush=True)


def _warm_up_scheduler(names: Sequence[str]) -> str:
    """The scheduler of the warm-up run (not recorded): one that uses the cloud, so that every code path (actor
    imports, the cloud link) is hot before the measured runs."""
    return next((c.name for c in iter_schedulers(names) if c.uses_cloud), names[0])


def run_schedulers(schedulers: Sequence[str] | None = None, loads: Sequence[str] = ("MEDIUM",), drones: int = 80,
                   duration_s: float = 60.0, seed: int = 0, drones_per_edge: int = DEFAULT_DRONES_PER_EDGE,
                   fps: float = DEFAULT_FPS, network: Sequence[str] | None = None,
                   edge_jitter: str = "lognormal:0.05", cloud_jitter: str = "lognormal:0.1", cloud_nodes: int = 1,
                   cloud_executors: int | None = None, edge_hosts: int | None = None, address: str | None = None,
                   repeat: int = 1, drain_s: float = 10.0, workload_path: str | os.PathLike | None = None,
                   progress: bool = True, reply_lead_ms: float = 100.0, seeds: int = 1,
                   cloud_sigmas: Sequence[float] | None = None, scenarios: Sequence[str] | None = None,
                   options: dict | None = None, emulation_bound_ms: float = EMULATION_BOUND_MS, trace=None) -> dict:
    """Run the benchmark; returns the JSON-able result (see the module docstring): ``runs`` (one row per
    scheduler, load, cloud sigma, scenario and seed ``seed .. seed + seeds - 1``) and ``results`` (per scheduler,
    load, sigma and scenario: every figure as mean ± 95 % CI over the seeds, :func:`summarize_runs`).
    ``cloud_sigmas``: lognormal cloud jitter sigmas to sweep (overrides ``cloud_jitter``); ``scenarios``: network
    scenarios of :mod:`aerodaas.bench.sweep` added to ``network``; ``options``: scheduler options (``estimator``,
    ``eviction_scan``) for every policy that accepts them; ``trace``: the arrival process
    (:class:`aerodaas.bench.traces.TraceSpec`, default periodic). A run whose worst emulation timing error p99 exceeds
    ``emulation_bound_ms`` is marked invalid. Raises ValueError for an unknown scheduler or load, or bad numbers,
    before starting Ray."""
    trace_spec = trace
    names, jitters, scen, nets, wpath, workloads, opts = _checked(
        schedulers, loads, repeat, cloud_nodes, reply_lead_ms, seeds, edge_jitter, cloud_jitter, network,
        cloud_sigmas, scenarios, duration_s, workload_path, options)
    n_edges = len(edge_layout(drones, drones_per_edge))
    host_edges = _host_edges(edge_hosts, n_edges)
    n_hosts = len(host_edges)
    say = functools.partial(_say, progress)

    cluster = _Cluster(address, cloud_nodes)
    results, t_all = [], time.time()
    hosts, cloud = [], []

    try:
        nodes = cluster.nodes()
        hosts, cloud = _start_actors(nodes, address, cloud_executors, n_hosts)
        host_info = ray.get([h.info.remote() for h in hosts])
        cloud_info = ray.get([c.info.remote() for c in cloud])
        say(f"cluster: {len(nodes)} nodes; {n_edges} edges on {n_hosts} host actor(s); {len(cloud)} cloud "
            "executor(s)")
        host_of = {e: i for i, es in enumerate(host_edges) for e in es}
        warm = make_trace(workloads[loads[0]], min(drones, 2 * drones_per_edge), 0.6, seed + 7919, drones_per_edge, fps)
        _run_one(hosts, host_edges, cloud, _warm_up_scheduler(names), workloads[loads[0]],
                 [[r for r in warm if host_of[r[1]] == i] for i in range(n_hosts)], seed=seed,
                 edge_jitter=edge_jitter, cloud_jitter=cloud_jitter, network=network, drain_s=drain_s,
                 reply_lead_ms=reply_lead_ms)  # warm-up, not recorded (see _warm_up_scheduler)
        for load, (sigma, cj), sc, sd in itertools.product(loads, jitters, scen, range(seed, seed + seeds)):
            w = workloads[load]
            trace = make_trace(w, drones, duration_s, sd, drones_per_edge, fps, trace_spec)
            by_host = [[r for r in trace if host_of[r[1]] == i] for i in range(n_hosts)]
            say(f"{load} cloud jitter {cj} network {sc} seed {sd}: {len(trace)} tasks from {drones} drones over "
                f"{duration_s:g} s (load average {os.getloadavg()[0]:.2f})")
            for name in names:
                reps = [_measure(hosts, host_edges, cloud, name, w, by_host, k, say, seed=sd, edge_jitter=edge_jitter,
                                 cloud_jitter=cj, network=nets[sc], drain_s=drain_s, reply_lead_ms=reply_lead_ms,
                                 options=opts[name], shape=(load, drones, n_edges, drones_per_edge))
                        for k in range(repeat)]
                row = _with_repeats(reps)
                row.update(seed=sd, cloud_sigma=sigma, cloud_jitter=cj, scenario=sc,
                           load_avg_1min=round(os.getloadavg()[0], 2), emulation_p99_ms=_emulation_p99(row),
                           emulation_valid=_emulation_p99(row) <= emulation_bound_ms)
                results.append(row)
    finally:
        _kill(ray, (*hosts, *cloud))
        cluster.close()
    return {
        "benchmark": "schedulers", "mode": "runtime", "machine": machine_info(), "seed": seed,
        "seeds": list(range(seed, seed + seeds)),
        "config": _config(names, loads, drones, drones_per_edge, n_edges, fps, duration_s, repeat, trace_spec,
                          edge_jitter, cloud_jitter, network, seed, cloud_nodes, address, n_hosts, len(cloud), wpath,
                          reply_lead_ms, jitters, scen, options, emulation_bound_ms, drain_s),
        "cluster": {"nodes": nodes, "edge_hosts": host_info, "cloud_executors": cloud_info},
        "laplan_planner": _planner_of(host_info),
        "arrival_process": _arrival_process(trace_spec, fps, drones_per_edge),
        "runs": results, "results": summarize_runs(results), "emulation": _emulation_summary(results),
        "wall_s": time.time() - t_all,
    }


def _planner_of(host_info: list[dict]) -> dict:
    """Whether LAPLAN's planner ran compiled where the policies ran, the edge host actors (their ``info``; see
    :func:`aerodaas.schedulers.single_machine_jit.status`): compiled only if on every host, ``why_not`` the first
    host's reason otherwise, and each host's own value in ``per_host``."""
    per = [h["laplan_planner"] for h in host_info]
    return {"compiled": all(p["compiled"] for p in per),
            "why_not": next((p["why_not"] for p in per if not p["compiled"]), None),
            "per_host": {h["name"]: h["laplan_planner"]["compiled"] for h in host_info}}


def _with_repeats(reps: list[dict]) -> dict:
    """One result row: the mean of the repeats for the headline numbers, each repeat's numbers, and the spread."""
    if len(reps) == 1:
        row = dict(reps[0])
        row["repeats"] = 1
        return row
    keys = ("on_time_rate", "utility", "cloud_cost", "edge_utilisation")
    row = dict(reps[0])
    for k in keys:
        row[k] = sum(r[k] for r in reps) / len(reps)
    row["repeats"] = len(reps)
    row["per_repeat"] = [{k: r[k] for k in (*keys, "drops")} for r in reps]
    row["spread"] = {k: max(r[k] for r in reps) - min(r[k] for r in reps) for k in keys}
    mean_u = abs(row["utility"]) or 1.0
    row["spread"]["utility_rel"] = row["spread"]["utility"] / mean_u
    return row


def _emulation_summary(results: list[dict]) -> dict:
    """Worst p99 / max of each timing error over all runs (ms), to judge the emulation's faithfulness."""
    out = {}
    for k in ("arrival_lateness", "edge_hold_error", "cloud_rtt_error", "poll_lateness", "cloud_reply_margin"):
        vals = [r["timing_ms"][k] for r in results if r["timing_ms"][k]["n"]]
        if k == "cloud_reply_margin":  # how early replies came (negative: late); the worst is the smallest
            out[k] = {"min_p50": min((v["p50"] for v in vals), default=0.0),
                      "min_p01": min((v["p01"] for v in vals if "p01" in v), default=0.0)}
            continue
        out[k] = {"worst_p50": max((v["p50"] for v in vals), default=0.0),
                  "worst_p99": max((v["p99"] for v in vals), default=0.0),
                  "worst_max": max((v["max"] for v in vals), default=0.0)}
    return out
