"""The fleet cost model: fitted to ``aerodaas bench fleet --edge-nodes N --json`` reports, it
projects the nodes a fleet of D drones needs — by CPU, by memory, by the per-node recorder's ceiling — the GCS's
actor count, and names what breaks first. Pure: JSON in, numbers out (no Ray, no clock); ``aerodaas bench
fleet-model RUN.json... [--drones 1000 --node-cores C --node-mem-gib M]`` prints it.

**Data.** Every row of every report (whose measuring window was whole) carries ``nodes`` (:func:`aerodaas.bench.fleet_nodes.node_report`): per node p
its drones d_p, CPU-seconds per simulated second by role ``cpu[role]_p`` over a window of the flight, PSS (MiB) by
role at the window's end and per drone actor, and its recorder's messages/s and MiB/s. Node 0 is the head (GCS,
driver).

**Fit** (ratio estimators over all node points; Σ over points p):

* CPU per drone, c_d = Σ_p (cpu[drone_actors]_p + cpu[recorder_actors]_p) / Σ_p d_p — the drone actors' work and
  the recorder's, which grows with the drones it records (CPU-s per drone per simulated second = cores per drone
  at speedup 1).
* Fixed CPU per edge node, c_n = mean over the non-head points (all points when a run had only the head) of
  (cpu[raylet] + cpu[ray_other]) (raylet, Ray's agents, log monitor, idle workers); the head's extra,
  c_h = max(0, mean over head points of (cpu[raylet] + cpu[ray_other] + cpu[gcs] + cpu[driver]) − c_n): the GCS,
  the driver and the agents only the head runs.
* PSS per drone actor, m_a = Σ_p Σ(drone actor PSS) / Σ_p (drone actors); per drone m_d = m_a / k (k drones per
  actor). Fixed PSS per edge node, m_n = mean over the non-head points (else all) of (pss[raylet] +
  pss[ray_other] + pss[recorder_actors]) (a recorder's memory is bounded by its queues, not by the drones); the
  head's extra m_h = max(0, mean over head points of (the same + pss[gcs] + pss[driver]) − m_n) (its GCS, driver,
  the run's own recorder and the head-only agents).
* Recorder load per drone, r_msg = Σ_p msgs/s_p / Σ_p d_p and r_mb = Σ_p MiB/s_p / Σ_p d_p (``recording.per_node``:
  each node's recorder records that node's drones).
* GCS actors: per run, from the GCS's count by class: drone actors per drone actor (1), node recorders per node
  g_n = mean((RecorderActor − 1) / nodes), everything else per run
  g_r = mean(total − DroneActor − node recorders).

**Projection** for D drones, k per actor, edge nodes of C cores and M GiB, one recorder's ceiling R_msg msgs/s and
R_mb MiB/s (``aerodaas bench recorder``, docs/results/recorder.md: about 8,000 msgs/s and 15 MiB/s):

* drones per node by CPU  n_cpu = floor((C − c_n) / c_d)
* drones per node by memory  n_mem = floor((1024 M − m_n) / m_d)
* drones per node by its recorder  n_rec = floor(min(R_msg / r_msg, R_mb / r_mb))
* nodes by each: ceil(D / n_x); edge nodes = the largest (the smallest n_x **breaks first**), plus one head
  (c_n + c_h CPU, m_n + m_h MiB; it carries drones in the measurement, not in the projection).
* GCS actors = ceil(D / k) + g_n × edge nodes + g_r, against the 10,000 actors of Ray's own release test
  (``release/benchmarks/distributed/test_many_actors.py``, ``many_actors.json``: 10,000 actors on one GCS).
* one recorder for the whole run (no ``recording.per_node``): it carries floor(min(R_msg / r_msg, R_mb / r_mb))
  drones.

All rates are per simulated second; the benchmark flies at speedup 1, so they are cores and MiB/s of wall time.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass

from aerodaas.bench.output import emit_report, print_report

__all__ = ["CostModel", "Projection", "Limit", "fit", "project", "format_projection", "main",
           "RAY_TESTED_ACTORS"]

#: actors on one GCS in Ray's release test ``many_actors`` (ray-project/ray, release/benchmarks: 10,000 actors)
RAY_TESTED_ACTORS = 10_000


@dataclass(frozen=True)
class CostModel:
    """The fitted costs (formulas: the module docstring). CPU in CPU-seconds per simulated second, memory in MiB,
    recorder load per drone in messages/s and MiB/s; ``points``: node samples fitted, ``runs``: fleet rows."""

    cpu_per_drone: float
    cpu_node_fixed: float
    cpu_head_extra: float
    pss_per_drone_actor: float
    pss_node_fixed: float
    pss_head_extra: float
    recorder_msgs_per_drone: float
    recorder_mb_per_drone: float
    gcs_actors_per_node: float
    gcs_actors_per_run: float
    drones_per_actor: int
    points: int
    runs: int


@dataclass(frozen=True)
class Limit:
    """One resource's limit: drones one edge node carries by it, and the edge nodes D drones need by it."""

    resource: str
    drones_per_node: int
    nodes: int


@dataclass(frozen=True)
class Projection:
    """A fleet of ``drones`` on edge nodes of ``node_cores`` cores and ``node_mem_gib`` GiB: the limits (smallest
    ``drones_per_node`` first: ``limits[0]`` breaks first), the edge nodes needed, the head's cost, the GCS's
    actors, and the drones one recorder for the whole run would carry."""

    drones: int
    node_cores: float
    node_mem_gib: float
    limits: list[Limit]
    edge_nodes: int
    breaks_first: str
    head_cpu: float
    head_pss_mb: float
    gcs_actors: int
    gcs_actors_tested_by_ray: int
    single_recorder_drones: int


def _points(reports: list[dict]) -> tuple[list[dict], list[dict]]:
    """(node points, rows) of every row with ``nodes`` in ``reports`` whose measuring window was whole (a row whose
    run ended before its window closed is left out). Raises ValueError when there are none."""
    rows = [r for rep in reports for r in rep.get("results", [])
            if r.get("nodes") and (r.get("window") or {}).get("complete", True)]
    if not rows:
        raise ValueError("no row with 'nodes' in the reports: run `aerodaas bench fleet --edge-nodes N --json`")
    return [p for r in rows for p in r["nodes"]], rows


def _mean(xs: list[float]) -> float:
    return sum(xs) / len(xs) if xs else 0.0


#: the roles of a node's fixed cost (CPU; PSS also counts its recorder) and of the head's extra
_CPU_FIXED, _PSS_FIXED, _HEAD = ("raylet", "ray_other"), ("raylet", "ray_other", "recorder_actors"), ("gcs", "driver")


def _sum(by_role: dict[str, float], roles: tuple[str, ...]) -> float:
    return sum(by_role.get(r, 0.0) for r in roles)


def _ratio(num: float, den: float, what: str) -> float:
    if den <= 0:
        raise ValueError(f"cannot fit {what}: no node carried a drone in the reports")
    return num / den


def fit(reports: list[dict]) -> CostModel:
    """The :class:`CostModel` of the node points of ``reports`` (``bench fleet --edge-nodes N`` JSON, as dicts).
    Raises ValueError when no row has nodes or no node carried drones, or the rows mix drones per actor."""
    points, rows = _points(reports)
    ks = {int(r.get("drones_per_actor", 1)) for r in rows}
    if len(ks) != 1:
        raise ValueError(f"the reports mix drones per actor {sorted(ks)}: fit one grouping at a time")
    drones = sum(p["drones"] for p in points)
    cpu = {role: sum(p["cpu_s_per_sim_s"].get(role, 0.0) for p in points) for role in ("drone_actors",
                                                                                       "recorder_actors")}
    heads = [p for p in points if p.get("head")]
    edges = [p for p in points if not p.get("head")] or points
    cpu_node = _mean([_sum(p["cpu_s_per_sim_s"], _CPU_FIXED) for p in edges])
    pss_node = _mean([_sum(p["pss_mb"], _PSS_FIXED) for p in edges])
    actor_pss = [(p["pss_mb_per_drone_actor"], len(p["drone_actors"])) for p in points
                 if p.get("pss_mb_per_drone_actor") is not None]
    rec = [p["recorder"] for p in points if p.get("recorder")]
    rec_drones = sum(p["drones"] for p in points if p.get("recorder"))
    classes = [(r.get("gcs_actor_classes") or {}, int(r.get("gcs_actors", 0)), len(r["nodes"])) for r in rows]
    node_recorders = [max(c.get("RecorderActor", 0) - 1, 0) / n for c, _, n in classes]
    per_run = [t - c.get("DroneActor", 0) - max(c.get("RecorderActor", 0) - 1, 0) for c, t, _ in classes]
    return CostModel(
        cpu_per_drone=_ratio(cpu["drone_actors"] + cpu["recorder_actors"], drones, "CPU per drone"),
        cpu_node_fixed=cpu_node,
        cpu_head_extra=max(0.0, _mean([_sum(p["cpu_s_per_sim_s"], _CPU_FIXED + _HEAD) for p in heads]) - cpu_node),
        pss_per_drone_actor=_ratio(sum(m * n for m, n in actor_pss), sum(n for _, n in actor_pss),
                                   "PSS per drone actor"),
        pss_node_fixed=pss_node,
        pss_head_extra=max(0.0, _mean([_sum(p["pss_mb"], _PSS_FIXED + _HEAD) for p in heads]) - pss_node),
        recorder_msgs_per_drone=(sum(r["messages_per_s"] for r in rec) / rec_drones) if rec_drones else 0.0,
        recorder_mb_per_drone=(sum(r["mb_per_s"] for r in rec) / rec_drones) if rec_drones else 0.0,
        gcs_actors_per_node=_mean(node_recorders), gcs_actors_per_run=_mean([float(x) for x in per_run]),
        drones_per_actor=ks.pop(), points=len(points), runs=len(rows))


def _capacity(budget: float, per_drone: float) -> int:
    """Drones that fit ``budget`` at ``per_drone`` each (0 when the fixed cost already exceeds the node; a
    resource a drone does not use: unbounded, as a large int)."""
    if per_drone <= 0:
        return sys.maxsize
    return max(int(math.floor(budget / per_drone)), 0)


def project(model: CostModel, drones: int = 1000, node_cores: float = 2.0, node_mem_gib: float = 8.0,
            recorder_msgs_per_s: float = 8000.0, recorder_mb_per_s: float = 15.0,
            mb_per_drone: float | None = None) -> Projection:
    """The :class:`Projection` of ``drones`` drones on edge nodes of ``node_cores`` cores and ``node_mem_gib``
    GiB, one recorder per node with the given ceilings (formulas: the module docstring). ``mb_per_drone``: the
    recorded MiB/s of one drone instead of the fitted r_mb (e.g. a real camera's frames: the benchmark's
    simulated ground compresses to a few KB a frame). Raises ValueError for drones < 1 or a node with no cores or
    memory, or when a node cannot carry one drone."""
    if drones < 1 or node_cores <= 0 or node_mem_gib <= 0:
        raise ValueError(f"drones must be >= 1 and the node's cores and memory > 0, got drones={drones}, "
                         f"node_cores={node_cores}, node_mem_gib={node_mem_gib}")
    per_rec = min(_capacity(recorder_msgs_per_s, model.recorder_msgs_per_drone),
                  _capacity(recorder_mb_per_s, model.recorder_mb_per_drone if mb_per_drone is None else mb_per_drone))
    caps = {"CPU": _capacity(node_cores - model.cpu_node_fixed, model.cpu_per_drone),
            "memory": _capacity(1024.0 * node_mem_gib - model.pss_node_fixed,
                                model.pss_per_drone_actor / model.drones_per_actor),
            "recorder (one per node)": per_rec}
    limits = sorted((Limit(res, cap, math.ceil(drones / cap) if cap else 0) for res, cap in caps.items()),
                    key=lambda lim: lim.drones_per_node)
    if limits[0].drones_per_node < 1:
        raise ValueError(f"an edge node of {node_cores} cores and {node_mem_gib} GiB cannot carry one drone by "
                         f"{limits[0].resource} (its fixed cost is {model.cpu_node_fixed:.3f} CPU, "
                         f"{model.pss_node_fixed:.0f} MiB)")
    nodes = limits[0].nodes
    return Projection(drones=drones, node_cores=node_cores, node_mem_gib=node_mem_gib, limits=limits,
                      edge_nodes=nodes, breaks_first=limits[0].resource,
                      head_cpu=model.cpu_node_fixed + model.cpu_head_extra,
                      head_pss_mb=model.pss_node_fixed + model.pss_head_extra,
                      gcs_actors=math.ceil(drones / model.drones_per_actor) + math.ceil(
                          model.gcs_actors_per_node * nodes + model.gcs_actors_per_run),
                      gcs_actors_tested_by_ray=RAY_TESTED_ACTORS, single_recorder_drones=per_rec)


def format_projection(model: CostModel, p: Projection) -> str:
    """The fit and the projection as text (a Markdown table of the limits)."""
    big = "unbounded"
    lines = [f"fit: {model.runs} run(s), {model.points} node point(s), {model.drones_per_actor} drone(s) per actor",
             f"  CPU per drone {model.cpu_per_drone:.4f} CPU-s/sim-s; per node {model.cpu_node_fixed:.4f}; "
             f"head extra (GCS, driver) {model.cpu_head_extra:.4f}",
             f"  PSS per drone actor {model.pss_per_drone_actor:.1f} MiB; per node {model.pss_node_fixed:.0f} MiB; "
             f"head extra {model.pss_head_extra:.0f} MiB",
             f"  recorder per drone {model.recorder_msgs_per_drone:.1f} msg/s, {model.recorder_mb_per_drone:.3f} MiB/s;"
             f" GCS actors per node {model.gcs_actors_per_node:.2f}, per run {model.gcs_actors_per_run:.2f}",
             f"projection: {p.drones} drones on edge nodes of {p.node_cores:g} cores, {p.node_mem_gib:g} GiB",
             "| limit | drones per node | edge nodes needed |", "|---|---|---|"]
    for lim in p.limits:
        cap = big if lim.drones_per_node == sys.maxsize else f"{lim.drones_per_node:,}"
        lines.append(f"| {lim.resource} | {cap} | {lim.nodes:,} |")
    lines += [f"edge nodes: {p.edge_nodes:,} + 1 head ({p.head_cpu:.3f} CPU, {p.head_pss_mb:.0f} MiB); "
              f"breaks first: {p.breaks_first}",
              f"GCS actors: {p.gcs_actors:,} (Ray's release test: {p.gcs_actors_tested_by_ray:,} on one GCS)",
              "one recorder for the whole run (no recording.per_node) carries "
              + (big if p.single_recorder_drones == sys.maxsize else f"{p.single_recorder_drones:,}") + " drones"]
    return "\n".join(lines)


def main(a: argparse.Namespace) -> int:
    """``aerodaas bench fleet-model``: reads the reports, fits, projects and prints; exit 2 naming a bad file or
    value."""
    reports = []
    for path in a.reports:
        try:
            with open(path) as f:
                reports.append(json.load(f))
        except (OSError, ValueError) as e:
            print(f"aerodaas bench fleet-model: cannot read report {path!r}: {e}", file=sys.stderr)
            return 2
    machine = reports[0].get("machine") or {}
    cores = a.node_cores if a.node_cores is not None else float(machine.get("cpu_count") or 0)
    mem = a.node_mem_gib if a.node_mem_gib is not None else float(machine.get("memory_gib") or 0)
    try:
        model = fit(reports)
        proj = project(model, a.drones, cores, mem, a.recorder_msgs_per_s, a.recorder_mb_per_s, a.mb_per_drone)
    except ValueError as e:
        print(f"aerodaas bench fleet-model: {e}", file=sys.stderr)
        return 2
    if a.json or a.out:
        # machine: where the runs were measured (the first report's), as every benchmark's report names it
        emit_report({"benchmark": "fleet-model", "machine": machine, "reports": list(a.reports),
                     "model": asdict(model), "projection": asdict(proj)}, a.out, a.json)
    if not a.json:
        print_report(format_projection(model, proj))
    return 0
