"""``aerodaas bench schedulers``: analytics schedulers on one seeded drone-fleet trace, on real Ray actors.

Every scheduler (all registered ones by default) runs the SAME arrival trace, in emulated mode, with wall-clock
time, on a local multi-node Ray cluster (one ``tier=edge`` node, ``--cloud-nodes`` ``tier=cloud`` nodes; see
:mod:`aerodaas.clusters.local`) or on the cluster at ``--address``:

* edge devices: ``ceil(drones / drones_per_edge)`` emulated edge accelerators, each an
  :class:`~aerodaas.edgecloud.AnalyticsDispatcher` with its own policy instance, hosted by a few
  :class:`~aerodaas.edgecloud.EdgeHost` actors on the edge node (many devices per process: the tasks are timers);
* cloud: :class:`~aerodaas.edgecloud.CloudExecutor` actors on the cloud nodes (Lambda-like, unbounded
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

import argparse
import json
import math
import os
import random
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Sequence

from aerodaas.bench import machine_info
from aerodaas.bench.tours import _positive as _positive_int  # argparse type: an integer >= 1

LOADS = ("LIGHT", "MEDIUM", "HEAVY")
DEFAULT_DRONES_PER_EDGE = 3
DEFAULT_FPS = 1.0


# ---------------------------------------------------------------------------------------------- workload and trace
def default_workload_path() -> Path:
    """``$AERODAAS_DATA_DIR/workloads/ocularone_lambda.json`` (default data dir: ``../shared/data`` of the repo)."""
    base = os.environ.get("AERODAAS_DATA_DIR") or str(Path(__file__).resolve().parents[2].parent / "shared" / "data")
    return Path(base) / "workloads" / "ocularone_lambda.json"


def edge_layout(drones: int, drones_per_edge: int) -> list[list[str]]:
    """Drones ``d000..`` assigned to edges in order, ``drones_per_edge`` each (the last edge may have fewer).
    Raises ValueError for non-positive counts."""
    if drones < 1:
        raise ValueError(f"drones must be >= 1, got {drones}")
    if drones_per_edge < 1:
        raise ValueError(f"drones_per_edge must be >= 1, got {drones_per_edge}")
    names = [f"d{i:03d}" for i in range(drones)]
    return [names[i:i + drones_per_edge] for i in range(0, drones, drones_per_edge)]


def make_trace(workload, drones: int, duration_s: float, seed: int, drones_per_edge: int = DEFAULT_DRONES_PER_EDGE,
               fps: float = DEFAULT_FPS) -> list[tuple[float, str, str, str]]:
    """The arrival trace: rows ``(arrival_ms, edge_id, drone, model)`` sorted by time, for frames sent in
    ``[0, duration_s)``. Each drone sends a frame every ``1/fps`` s from a seeded phase in ``[0, 1/fps)``; each frame
    yields one task per model of ``workload`` in a seeded shuffled order. Raises ValueError for bad parameters."""
    if not duration_s > 0:
        raise ValueError(f"duration must be > 0 s, got {duration_s}")
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    rng = random.Random(seed)
    period_ms = 1000.0 / fps
    models = list(workload.models)
    rows = []
    for e, group in enumerate(edge_layout(drones, drones_per_edge)):
        for drone in group:
            t = round(rng.uniform(0.0, period_ms), 3)
            while t < duration_s * 1000.0:
                order = models[:]
                rng.shuffle(order)
                rows.extend((t, f"edge{e:02d}", drone, m) for m in order)
                t = round(t + period_ms, 3)
    rows.sort(key=lambda r: r[0])  # stable: keeps each frame's shuffled model order
    return rows


# ---------------------------------------------------------------------------------------------- cluster
class _Cluster:
    """The benchmark's Ray cluster: a LocalCluster it started, or the cluster at ``address``."""

    def __init__(self, address: str | None, cloud_nodes: int) -> None:
        import ray

        self.local = None
        if address:
            if not ray.is_initialized():
                ray.init(address=address, include_dashboard=False, logging_level="warning")
        else:
            if ray.is_initialized():
                ray.shutdown()
            from aerodaas.clusters.local import LocalCluster

            self.local = LocalCluster(cloud_nodes=cloud_nodes, edge_cpus=2, cloud_cpus=2, worker_niceness=0)

    def nodes(self) -> list[dict]:
        import ray

        return [{"node_id": n["NodeID"], "labels": {k: v for k, v in n.get("Labels", {}).items()
                                                     if not k.startswith("ray.io/")}}
                for n in ray.nodes() if n.get("Alive")]

    def close(self) -> None:
        if self.local is not None:
            self.local.shutdown()


def _pooled(values: list[float]) -> dict:
    from aerodaas.edgecloud import Samples

    return Samples.summarize(values)


# ---------------------------------------------------------------------------------------------- one run
def _merge(name: str, load: str, drones: int, n_edges: int, per_edge: int, host_outs: list[dict], wall_s: float
           ) -> dict:
    edges = [r for out in host_outs for r in out["edges"]]
    c = Counter()
    states, tiers, drops, reasons = Counter(), Counter(), Counter(), Counter()
    ubm, tbm, obm = Counter(), Counter(), Counter()
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
        "cloud_losses": losses, "wall_s": wall_s,
    }


def _run_one(hosts, host_edges: list[list[str]], cloud, name: str, workload, trace_by_host, *, seed: int,
             edge_jitter: str, cloud_jitter: str, network: Sequence[str] | None, drain_s: float,
             reply_lead_ms: float) -> list[dict]:
    import ray

    t = time.time()
    start_epoch = time.time() + 0.5 + 0.02 * sum(len(e) for e in host_edges) / max(1, len(hosts))
    ray.get([h.configure.remote(scheduler=name, workload=workload, edge_ids=edges, cloud_executors=cloud,
                                start_epoch=start_epoch, edge_jitter=edge_jitter, cloud_jitter=cloud_jitter,
                                network=network, seed=seed, reply_lead_ms=reply_lead_ms)
            for h, edges in zip(hosts, host_edges)])
    if time.time() > start_epoch:
        raise RuntimeError("configuring the edge hosts took longer than the run's lead time")
    outs = ray.get([h.run_trace.remote(tr, drain_s) for h, tr in zip(hosts, trace_by_host)])
    ray.get([h.close.remote() for h in hosts])
    return outs + [{"wall_s": time.time() - t}]


def run_schedulers(schedulers: Sequence[str] | None = None, loads: Sequence[str] = ("MEDIUM",), drones: int = 80,
                   duration_s: float = 60.0, seed: int = 0, drones_per_edge: int = DEFAULT_DRONES_PER_EDGE,
                   fps: float = DEFAULT_FPS, network: Sequence[str] | None = None,
                   edge_jitter: str = "lognormal:0.05", cloud_jitter: str = "lognormal:0.1", cloud_nodes: int = 1,
                   cloud_executors: int | None = None, edge_hosts: int | None = None, address: str | None = None,
                   repeat: int = 1, drain_s: float = 10.0, workload_path: str | os.PathLike | None = None,
                   progress: bool = True, reply_lead_ms: float = 100.0) -> dict:
    """Run the benchmark; returns the JSON-able result (see the module docstring). Raises ValueError for an
    unknown scheduler or load, or bad numbers, before starting Ray."""
    from aerodaas.edgecloud import EdgeHostActor, Jitter, NetworkModel, start_cloud_executors
    from aerodaas.schedulers.analytics_base import Workload, analytics_scheduler_names

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
    Jitter.parse(edge_jitter), Jitter.parse(cloud_jitter), NetworkModel.parse(network)  # validate early
    wpath = Path(workload_path) if workload_path else default_workload_path()
    if not wpath.is_file():
        raise ValueError(f"workload file not found: {wpath} (set AERODAAS_DATA_DIR or pass workload_path)")
    workloads = {ld: Workload.from_file(wpath, ld) for ld in loads}
    layout = edge_layout(drones, drones_per_edge)
    n_edges = len(layout)
    ncpu = os.cpu_count() or 2
    n_hosts = edge_hosts or (1 if ncpu <= 2 else min(n_edges, max(1, ncpu // 2)))
    n_hosts = max(1, min(n_hosts, n_edges))
    edge_ids = [f"edge{e:02d}" for e in range(n_edges)]
    host_edges = [edge_ids[i::n_hosts] for i in range(n_hosts)]

    def say(msg: str) -> None:
        if progress:
            print(f"[bench schedulers] {msg}", file=sys.stderr, flush=True)

    cluster = _Cluster(address, cloud_nodes)
    results, t_all = [], time.time()
    hosts, cloud = [], []
    import ray

    try:
        nodes = cluster.nodes()
        if not any(n["labels"].get("tier") == "edge" for n in nodes):
            raise ValueError(f"the cluster at {address!r} has no node labelled tier=edge (start the edge node with "
                             "`ray start --labels tier=edge`, see docs/clusters.md)")
        n_cloud_nodes = sum(1 for n in nodes if n["labels"].get("tier") == "cloud")
        cloud = start_cloud_executors(cloud_executors or max(1, n_cloud_nodes)) if (n_cloud_nodes or address) else []
        hosts = [EdgeHostActor.options(label_selector={"tier": "edge"}).remote(f"edge-host{i}")
                 for i in range(n_hosts)]
        host_info = ray.get([h.info.remote() for h in hosts])
        cloud_info = ray.get([c.info.remote() for c in cloud])
        say(f"cluster: {len(nodes)} nodes ({n_cloud_nodes} cloud); {n_edges} edges on {n_hosts} host actor(s); "
            f"{len(cloud)} cloud executor(s)")
        # warm-up, not recorded: one short run of a scheduler that uses the cloud, so every code path (actor
        # imports, the cloud link) is hot before the measured runs
        from aerodaas.schedulers.analytics_base import iter_schedulers

        w0 = workloads[loads[0]]
        host_of = {e: i for i, es in enumerate(host_edges) for e in es}
        warm_name = next((c.name for c in iter_schedulers(names) if c.uses_cloud), names[0])
        warm = make_trace(w0, min(drones, 2 * drones_per_edge), 0.6, seed + 7919, drones_per_edge, fps)
        _run_one(hosts, host_edges, cloud, warm_name, w0,
                 [[r for r in warm if host_of[r[1]] == i] for i in range(n_hosts)], seed=seed,
                 edge_jitter=edge_jitter, cloud_jitter=cloud_jitter, network=network, drain_s=drain_s,
                 reply_lead_ms=reply_lead_ms)
        for load in loads:
            w = workloads[load]
            trace = make_trace(w, drones, duration_s, seed, drones_per_edge, fps)
            by_host = [[r for r in trace if host_of[r[1]] == i] for i in range(n_hosts)]
            say(f"{load}: {len(trace)} tasks from {drones} drones over {duration_s:g} s")
            for name in names:
                reps = []
                for k in range(repeat):
                    outs = _run_one(hosts, host_edges, cloud, name, w, by_host, seed=seed, edge_jitter=edge_jitter,
                                    cloud_jitter=cloud_jitter, network=network, drain_s=drain_s,
                                    reply_lead_ms=reply_lead_ms)
                    wall = outs.pop()["wall_s"]
                    reps.append(_merge(name, load, drones, n_edges, drones_per_edge, outs, wall))
                    r = reps[-1]
                    say(f"{load} {name} #{k + 1}: on-time {100 * r['on_time_rate']:.1f}% utility {r['utility']:.0f} "
                        f"cloud cost {r['cloud_cost']:.0f} decision p50/p99 {r['decision_us']['p50']:.1f}/"
                        f"{r['decision_us']['p99']:.1f} us; arrival lateness p99 "
                        f"{r['timing_ms']['arrival_lateness']['p99']:.1f} ms ({wall:.0f} s)")
                results.append(_with_repeats(reps))
    finally:
        for actor in (*hosts, *cloud):  # on a shared cluster (--address) leave nothing behind
            try:
                ray.kill(actor)
            except Exception:
                pass
        cluster.close()
    return {
        "benchmark": "schedulers", "machine": machine_info(), "seed": seed,
        "config": {"schedulers": names, "loads": list(loads), "drones": drones, "drones_per_edge": drones_per_edge,
                   "edges": n_edges, "fps": fps, "duration_s": duration_s, "repeat": repeat,
                   "edge_jitter": edge_jitter, "cloud_jitter": cloud_jitter,
                   "network_variability": list(network or []), "network": NetworkModel.parse(network, seed).describe(),
                   "cloud_nodes": cloud_nodes if not address else None, "address": address,
                   "edge_hosts": n_hosts, "cloud_executors": len(cloud), "workload": str(wpath), "mode": "emulated",
                   "cloud_reply_lead_ms": reply_lead_ms, "worker_niceness": 0 if not address else None},
        "cluster": {"nodes": nodes, "edge_hosts": host_info, "cloud_executors": cloud_info},
        "arrival_process": {
            "per_drone": f"one frame every {1000.0 / fps:g} ms from a seeded random phase",
            "per_frame": "one task per active model, seeded shuffled order, same arrival time",
            "drones_per_edge": drones_per_edge,
            "source": "dream-lab/ocularone-scheduler: TaskCreation.java (one task per model per batch, shuffled), "
                      "DNNPerfModel keyed by frame count 1, conf/config.yaml batch_length 1 s; paper: >80 drones, "
                      ">25 VIPs, several drones per Jetson Nano edge (arXiv 2412.20860)"},
        "results": results, "emulation": _emulation_summary(results), "wall_s": time.time() - t_all,
    }


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


# ---------------------------------------------------------------------------------------------- output
def format_table(res: dict) -> str:
    """Human-readable summary of a :func:`run_schedulers` result."""
    cfg, m = res["config"], res["machine"]
    lines = [f"aerodaas bench schedulers: {cfg['drones']} drones ({cfg['drones_per_edge']} per edge, {cfg['edges']} "
             f"edges), {cfg['duration_s']:g} s at {cfg['fps']:g} fps, seed {res['seed']}, {m['cpu_count']} CPUs", ""]
    head = ("load", "scheduler", "tasks", "on-time %", "utility", "cloud cost", "drops t/c/e/f", "edge util",
            "dec p50 us", "dec p99 us")
    rows = []
    for r in res["results"]:
        d = r["drops"]
        rows.append((r["load"], r["scheduler"], str(r["tasks"]), f"{100 * r['on_time_rate']:.1f}", f"{r['utility']:.0f}",
                     f"{r['cloud_cost']:.0f}", f"{d.get('dropped_time', 0)}/{d.get('dropped_cost', 0)}/"
                     f"{d.get('expired_edge', 0)}/{d.get('failed', 0)}", f"{100 * r['edge_utilisation']:.0f}%",
                     f"{r['decision_us']['p50']:.1f}", f"{r['decision_us']['p99']:.1f}"))
    widths = [max(len(x) for x in col) for col in zip(head, *rows)]
    for row in (head, *rows):
        lines.append("  ".join(c.ljust(w) if i < 2 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths))))
    e = res["emulation"]
    lines += ["", "emulation timing error (worst over runs, ms): " + ", ".join(
        f"{k} p99 {v['worst_p99']:.1f} max {v['worst_max']:.1f}" for k, v in e.items() if "worst_p99" in v)]
    return "\n".join(lines)


def write_plot(res: dict, path: str | os.PathLike) -> None:
    """A comparison figure (PNG): per load, on-time rate, utility and terminal states by scheduler."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    loads = list(dict.fromkeys(r["load"] for r in res["results"]))
    fig, axes = plt.subplots(len(loads), 3, figsize=(15, 3.6 * len(loads)), squeeze=False)
    states = ["done_on_time", "done_late", "dropped_time", "dropped_cost", "expired_edge", "failed"]
    colors = ["#2a9d8f", "#8ab17d", "#e9c46a", "#f4a261", "#e76f51", "#6d597a"]
    for row, load in zip(axes, loads):
        rs = [r for r in res["results"] if r["load"] == load]
        names = [r["scheduler"] for r in rs]
        x = range(len(rs))
        row[0].bar(x, [100 * r["on_time_rate"] for r in rs], color="#2a9d8f")
        row[0].set_ylabel(f"{load}\non-time completion (%)")
        row[0].set_ylim(0, 100)
        row[1].bar(x, [r["utility"] for r in rs], color="#264653")
        row[1].set_ylabel("total utility")
        bottom = [0.0] * len(rs)
        for s, col in zip(states, colors):
            vals = [100 * r["states"].get(s, 0) / max(1, r["tasks"]) for r in rs]
            row[2].bar(x, vals, bottom=bottom, color=col, label=s)
            bottom = [b + v for b, v in zip(bottom, vals)]
        row[2].set_ylabel("terminal states (% of tasks)")
        for ax in row:
            ax.set_xticks(list(x))
            ax.set_xticklabels(names, rotation=30, ha="right")
            ax.grid(axis="y", alpha=0.3)
    axes[0][2].legend(fontsize=7, loc="upper right")
    cfg = res["config"]
    fig.suptitle(f"Analytics schedulers: {cfg['drones']} drones, {cfg['drones_per_edge']} per edge, "
                 f"{cfg['duration_s']:g} s, seed {res['seed']}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------- CLI
def _positive_float(s: str) -> float:
    v = float(s)
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {s}")
    return v


def _loads(s: str) -> list[str]:
    out = [x.strip().upper() for x in s.split(",") if x.strip()]
    bad = [x for x in out if x not in LOADS]
    if bad or not out:
        raise argparse.ArgumentTypeError(f"loads must be among {', '.join(LOADS)} (comma-separated), got {s!r}")
    return out


def add_parser(bench_subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``aerodaas bench schedulers`` on the ``bench`` sub-command's subparsers."""
    p = bench_subparsers.add_parser(
        "schedulers", help="analytics schedulers (edge/cloud placement) on one seeded drone-fleet trace",
        description="Every analytics scheduler on the same seeded arrival trace, emulated with wall-clock time on "
                    "Ray actors (edge node + cloud nodes): on-time rate, utility, cloud cost, drops, decision "
                    "latency, and the emulation's own timing error.")
    p.add_argument("--drones", type=_positive_int, default=80, help="drones in the fleet (default 80)")
    p.add_argument("--load", type=_loads, default=["MEDIUM"],
                   help="LIGHT, MEDIUM or HEAVY, or a comma-separated list (default MEDIUM)")
    p.add_argument("--duration", type=_positive_float, default=60.0, help="seconds of arrivals per run (default 60)")
    p.add_argument("--schedulers", nargs="+", metavar="NAME", help="schedulers to run (default: all registered)")
    p.add_argument("--seed", type=int, default=0, help="seed of the trace, jitter and network draws (default 0)")
    p.add_argument("--drones-per-edge", type=_positive_int, default=DEFAULT_DRONES_PER_EDGE,
                   help=f"drones linked to each edge device (default {DEFAULT_DRONES_PER_EDGE})")
    p.add_argument("--fps", type=_positive_float, default=DEFAULT_FPS,
                   help=f"frames (1-frame batches) per second per drone (default {DEFAULT_FPS:g})")
    p.add_argument("--network-variability", action="append", metavar="SPEC",
                   help="extra cloud latency: const:MS, normal:MEAN,SD, lognormal:MEDIAN,SIGMA, +MS@T1-T2 (episode, "
                        "seconds), walk:STEP,MAX[,EVERY]; repeatable")
    p.add_argument("--edge-jitter", default="lognormal:0.05", help="edge hold jitter (default lognormal:0.05)")
    p.add_argument("--cloud-jitter", default="lognormal:0.1", help="cloud hold jitter (default lognormal:0.1)")
    p.add_argument("--cloud-nodes", type=int, default=1, help="cloud nodes of the local cluster (default 1)")
    p.add_argument("--edge-hosts", type=_positive_int, help="edge host actors (default: 1 on <= 2 CPUs)")
    p.add_argument("--cloud-reply-lead-ms", type=float, default=100.0,
                   help="emulated cloud replies are sent this early and released when due (default 100; 0: off)")
    p.add_argument("--repeat", type=_positive_int, default=1, help="runs per scheduler and load (default 1)")
    p.add_argument("--address", help="run on this Ray cluster (e.g. 'auto') instead of starting a local one")
    p.add_argument("--json", action="store_true", help="print the result as JSON instead of a table")
    p.add_argument("--out", metavar="FILE", help="also write the JSON result to FILE")
    p.add_argument("--plot", metavar="PNG", help="write the comparison figure to PNG (default: next to --out with a "
                                                 ".png suffix, else bench_schedulers.png in the working folder)")
    p.set_defaults(func=_cmd)
    return p


def _cmd(args: argparse.Namespace) -> int:
    try:
        res = run_schedulers(args.schedulers, args.load, args.drones, args.duration, args.seed,
                             args.drones_per_edge, args.fps, args.network_variability, args.edge_jitter,
                             args.cloud_jitter, args.cloud_nodes, None, args.edge_hosts, args.address, args.repeat,
                             reply_lead_ms=args.cloud_reply_lead_ms)
    except ValueError as e:
        print(f"aerodaas bench schedulers: {e}", file=sys.stderr)
        return 2
    text = json.dumps(res, indent=2)
    try:
        if args.out:
            Path(args.out).write_text(text + "\n", encoding="utf-8")
        plot = args.plot or (str(Path(args.out).with_suffix(".png")) if args.out else "bench_schedulers.png")
        write_plot(res, plot)
        print(f"aerodaas bench schedulers: comparison figure written to {plot}", file=sys.stderr)
    except OSError as e:
        print(f"aerodaas bench schedulers: cannot write output: {e}", file=sys.stderr)
        return 2
    print(text if args.json else format_table(res))
    bad = [r for r in res["results"] if r["accounting"]["pending"] or r["accounting"]["terminal"] != r["tasks"]]
    return 1 if bad else 0
