"""``aerodaas bench schedulers --harness``: the analytics-scheduler sweep on the deterministic policy harness.

For every cell of loads x cloud jitter sigma x drones per edge x network scenario, and every seed, the runtime
benchmark's own arrival trace (:func:`aerodaas.bench.workload.make_trace`) is run through every scheduler with
the runtime's seeded timing draws (:mod:`aerodaas.bench.harness`), and through the LP upper bound
(:mod:`aerodaas.bench.bound`: the LP relaxation everywhere; for the loads in ``exact_bound_loads``, default HEAVY,
also the exact clairvoyant optimum and the non-anticipative bound on the expected utility of any online policy).
Every figure is reported as the mean over seeds with a 95 % confidence interval
(Student t, n - 1 degrees of freedom) and the per-seed values (:func:`mean_ci`). Jobs (cell, seed) run in
``processes`` worker processes; the result does not depend on their number or order.

Claims checked per cell (``claim`` in the JSON): the utility of ``ours`` against the best of ``BASELINES`` — the
ratio of the means, and whether the 95 % intervals overlap.
"""
from __future__ import annotations

import math
import multiprocessing
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Sequence

from aerodaas.bench.bound import Budget, bounded, lognormal_on_time_chance, lognormal_slack, utility_upper_bound
from aerodaas.bench.harness import Harness, fleet_tasks, run_fleet
from aerodaas.bench.machine import machine_info
from aerodaas.bench.options import LOADS, SCENARIOS
from aerodaas.bench.workload import default_workload_path, make_trace, scenario_specs
from aerodaas.schedulers import single_machine_jit
from aerodaas.schedulers.analytics_base import (Workload, analytics_scheduler_names, filter_options,
                                                make_analytics_scheduler)
from aerodaas.schedulers.dispatch.emulation import Jitter, NetworkModel

__all__ = ["Cell", "BOUND_NAMES", "mean_ci", "t95", "scenario_specs", "SCENARIOS", "run_sweep", "aggregate", "format_sweep",
           "DEFAULT_SCHEDULERS", "BASELINES", "OURS", "markdown_tables", "claims"]

DEFAULT_SCHEDULERS = ("EDGE_EDF", "CLOUD", "E+C", "DEM", "DEMS", "DEMS-A", "GEMS", "GAINPLAN", "EVPLAN", "LAPLAN")
#: the reference policies our scheduler must beat, and ours
BASELINES = ("DEM", "DEMS", "DEMS-A", "GEMS")
OURS = "LAPLAN"

#: the upper bounds a sweep reports (aerodaas.bench.bound)
BOUND_NAMES = {
    "lp": "LP relaxation: preemptive edge, fractional choice, clairvoyant edge times and cloud draws (every cell)",
    "exact": "exact offline optimum: non-preemptive edge, clairvoyant edge times and cloud draws; holds on every seed",
    "na": "non-anticipative: exact edge schedule on the realised edge occupancy, but each task earns its expected "
          "reward given its start time (edge) or send time (cloud); bounds the mean over seeds of any online policy",
}

# two-sided 95 % Student t quantiles, df 1..30 (above: 1.96 for df > 120, interpolated table otherwise)
_T95 = [12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145, 2.131,
        2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042]


def t95(df: int) -> float:
    """Two-sided 95 % quantile of Student's t with ``df`` degrees of freedom (table of any statistics text;
    ``scipy.stats.t.ppf(0.975, df)`` gives the same to 3 decimals). Raises ValueError for df < 1."""
    if df < 1:
        raise ValueError(f"degrees of freedom must be >= 1, got {df}")
    if df <= 30:
        return _T95[df - 1]
    return 2.021 if df <= 40 else 2.000 if df <= 60 else 1.980 if df <= 120 else 1.960


def mean_ci(values: Sequence[float]) -> dict:
    """``{"mean", "ci95", "per_seed"}``: the mean, the half-width of its 95 % confidence interval (Student t,
    sample standard deviation; 0 for a single value, where the interval is unknown — ``n`` says so) and the
    values. Raises ValueError for no values."""
    xs = [float(v) for v in values]
    if not xs:
        raise ValueError("mean_ci needs at least one value")
    n = len(xs)
    m = sum(xs) / n
    half = t95(n - 1) * math.sqrt(sum((x - m) ** 2 for x in xs) / (n - 1)) / math.sqrt(n) if n > 1 else 0.0
    return {"mean": m, "ci95": half, "n": n, "per_seed": xs}


@dataclass(frozen=True)
class Cell:
    """One configuration of the sweep."""

    load: str
    cloud_sigma: float
    drones_per_edge: int
    scenario: str


def _send_times(net, task) -> list[float]:
    """Send times worth trying for the oracle: the arrival and every change of the network's offset in the window."""
    out = [task.arrival_ms]
    for e in net.episodes:
        for b in (e.start_s * 1000.0, e.end_s * 1000.0):
            if task.arrival_ms < b <= task.deadline_ms:
                out.append(b)
    if net.walk is not None:
        every = net.walk[2] * 1000.0
        k = math.floor(task.arrival_ms / every) + 1
        while k * every <= task.deadline_ms:
            out.append(k * every)
            k += 1
    return out


def _bounds(per_edge: dict, w, specs: list[str], seed: int, ej, cj, exact: bool, budget=None) -> dict:
    """The upper bounds of one (cell, seed), summed over the edges (see :mod:`aerodaas.bench.bound`): ``lp``
    always; with ``exact``, ``exact`` (clairvoyant, non-preemptive) and ``na`` (non-anticipative: expected cloud
    value and expected edge reward by start time; only for lognormal or no edge jitter). Each exact DP of an edge
    runs under ``budget`` (:class:`aerodaas.bench.bound.Budget`, default one): a bound of which some edge ran out is
    None, and ``not_computed`` says which (``{"exact": "time on edge03", ...}``); the LP is always there beside it."""
    budget = budget or Budget()
    out: dict = {"lp": 0.0}
    if exact:
        out["exact"] = 0.0
        if ej.kind in ("none", "lognormal"):
            out["na"] = 0.0
    missing: dict[str, str] = {}
    sigma_e = ej.sigma if ej.kind == "lognormal" else 0.0
    for edge, tasks in per_edge.items():
        net = NetworkModel.parse(specs, seed)
        h = Harness(make_analytics_scheduler("CLOUD", w), edge_jitter=ej, cloud_jitter=cj, network=net, seed=seed,
                    edge_id=edge)
        sends = lambda t, net=net: _send_times(net, t)  # noqa: E731
        out["lp"] += utility_upper_bound(tasks, w, h.edge_hold_ms, h.cloud_round_trip_ms, sends)["bound"]

        def chance(t, s, net=net):
            return lognormal_on_time_chance(w[t.model].cloud_ms, cj.sigma, t.deadline_ms - s, net.offset_ms(s))

        kw = {"exact": {}, "na": {"cloud_chance": chance,
                                  "edge_slack": lambda t, c: lognormal_slack(w[t.model].edge_ms, sigma_e, c)}}
        for name in [k for k in ("exact", "na") if k in out]:
            if out[name] is None:
                continue  # an earlier edge ran out: the sum is not computed anyway
            status, value = bounded(lambda kw_=kw[name]: utility_upper_bound(
                tasks, w, h.edge_hold_ms, h.cloud_round_trip_ms, sends, method="exact", **kw_)["bound"], budget)
            if status == "ok":
                out[name] += value
            else:
                out[name] = None
                missing[name] = f"{status} budget ran out on {edge} ({budget.time_s:g} s, {budget.memory_mb:g} MiB)"
    if missing:
        out["not_computed"] = missing
    return out


def _job(args: tuple) -> dict:
    """One (cell, seed): every scheduler and the upper bounds on the same trace. Runs in a worker process."""
    cell, seed, drones, duration_s, fps, names, options, edge_jitter, wpath, bound, exact, trace, budget = args
    t0 = time.process_time()
    w = Workload.from_file(wpath, cell.load)
    specs = scenario_specs(cell.scenario, duration_s)
    ej, cj = Jitter.parse(edge_jitter), Jitter("lognormal", cell.cloud_sigma)
    per_edge = fleet_tasks(make_trace(w, drones, duration_s, seed, cell.drones_per_edge, fps, trace), w)
    out = {"cell": asdict(cell), "seed": seed, "edges": len(per_edge), "results": {}}
    for name in names:
        out["results"][name] = run_fleet(name, w, per_edge, seed=seed, edge_jitter=ej, cloud_jitter=cj,
                                         network_specs=specs, options=options)
    if bound:
        out["bounds"] = _bounds(per_edge, w, specs, seed, ej, cj, exact, budget)
    out["cpu_s"] = time.process_time() - t0
    return out


def run_sweep(*, loads: Sequence[str], sigmas: Sequence[float], drones_per_edge: Sequence[int],
              scenarios: Sequence[str], scenario_loads: Sequence[str] | None = None, seeds: Sequence[int],
              drones: int | None = None, edges: int = 4, duration_s: float = 60.0, fps: float = 1.0,
              schedulers: Sequence[str] | None = None, options: dict | None = None,
              edge_jitter: str = "lognormal:0.05", workload_path: str | os.PathLike | None = None,
              processes: int | None = None, bound: bool = True, exact_bound_loads: Sequence[str] = ("HEAVY",),
              progress=None, trace=None, bound_budget=None) -> dict:
    """Run the sweep; returns the JSON-able result (``config``, ``cells``, ``results``, ``jobs``).

    ``drones``: fleet size per run (default ``edges`` x drones per edge). Scenarios other than ``"none"`` are run
    only for the loads in ``scenario_loads`` (default: HEAVY). ``options``: scheduler options applied to every
    policy that accepts them (``estimator``, ``eviction_scan``). ``bound``: compute the LP bound of every cell, and
    for the loads in ``exact_bound_loads`` the exact and the non-anticipative bounds too (seconds per edge at
    HEAVY; at MEDIUM the long deadlines make the exact one slow, and the LP is already within 1 % of the best
    policy there). ``trace``: the arrival process (:class:`aerodaas.bench.traces.TraceSpec`; default periodic).
    ``bound_budget``: the time and memory each edge's exact DP may use (:class:`aerodaas.bench.bound.Budget`;
    default 120 s, 1 GiB): past it the bound is reported "not computed", with the LP bound beside it.
    Raises ValueError for bad parameters, before any work starts."""
    names = list(schedulers or DEFAULT_SCHEDULERS)
    wpath = _checked(names, loads, sigmas, drones_per_edge, scenarios, seeds, duration_s, edge_jitter, workload_path,
                     options)

    budget = bound_budget or Budget()
    scenario_loads = list(scenario_loads or ["HEAVY"])
    cells = [Cell(ld, float(s), int(d), sc) for sc in scenarios for ld in loads for d in drones_per_edge
             for s in sigmas if sc == "none" or ld in scenario_loads]
    jobs = [(c, seed, drones or edges * c.drones_per_edge, duration_s, fps, names, dict(options or {}), edge_jitter,
             wpath, bound, bound and c.load in exact_bound_loads, trace, budget) for c in cells for seed in seeds]
    procs = processes or min(2, os.cpu_count() or 1)
    t0 = time.time()
    done = _run_jobs(jobs, procs, progress)
    done.sort(key=lambda r: (cells.index(Cell(**r["cell"])), r["seed"]))
    results = aggregate(done, names)
    return {
        "benchmark": "schedulers", "mode": "harness", "machine": machine_info(),
        # compiled or not shapes LAPLAN's plans (reduced to fit the kernel only then); the workers are this
        # process's children, with its packages and environment
        "laplan_planner": single_machine_jit.status(),
        "config": {"schedulers": names, "loads": list(loads), "cloud_sigma": list(sigmas),
                   "drones_per_edge": list(drones_per_edge), "scenarios": list(scenarios),
                   "scenario_loads": scenario_loads, "scenario_specs": {s: SCENARIOS[s] for s in scenarios},
                   "seeds": list(seeds), "drones": drones, "edges_per_run": None if drones else edges,
                   "duration_s": duration_s, "fps": fps, "edge_jitter": edge_jitter,
                   "trace": asdict(trace) if trace is not None else None,
                   "trace_label": trace.label() if trace is not None else "periodic",
                   "cloud_jitter": "lognormal:<cloud_sigma>", "options": dict(options or {}), "workload": wpath,
                   "processes": procs, "bounds": BOUND_NAMES if bound else None,
                   "exact_bound_loads": list(exact_bound_loads) if bound else [], "ours": OURS,
                   "exact_bound_budget": asdict(budget) if bound else None,
                   "baselines": list(BASELINES)},
        "results": results, "claims": claims(results),
        "wall_s": time.time() - t0, "cpu_s": sum(r["cpu_s"] for r in done),
    }


def _checked(names, loads, sigmas, drones_per_edge, scenarios, seeds, duration_s, edge_jitter, workload_path,
             options) -> str:
    """The sweep's parameters checked before any work (ValueError naming the field); returns the workload's path.
    Every scheduler is built once with its options, so a bad option value fails here, not in a worker."""
    unknown = [n for n in names if n not in analytics_scheduler_names()]
    if unknown:
        raise ValueError(f"schedulers: unknown {unknown}; registered: {analytics_scheduler_names()}")
    if any(ld not in LOADS for ld in loads) or not loads:
        raise ValueError(f"load: choose from {list(LOADS)}, got {list(loads)}")
    if any(not (s >= 0 and math.isfinite(s)) for s in sigmas) or not sigmas:
        raise ValueError(f"cloud_sigma: finite numbers >= 0 needed, got {list(sigmas)}")
    if any(d < 1 for d in drones_per_edge) or not drones_per_edge:
        raise ValueError(f"drones_per_edge: integers >= 1 needed, got {list(drones_per_edge)}")
    for s in scenarios:
        scenario_specs(s, duration_s)
    if not seeds:
        raise ValueError("seeds: at least one seed is needed")
    if not duration_s > 0:
        raise ValueError(f"duration must be > 0 s, got {duration_s}")
    Jitter.parse(edge_jitter)
    wpath = str(workload_path or default_workload_path())
    if not Path(wpath).is_file():
        raise ValueError(f"workload file not found: {wpath} (set AERODAAS_DATA_DIR)")
    w0 = Workload.from_file(wpath, loads[0])
    for n in names:
        make_analytics_scheduler(n, w0, **filter_options(n, options or {}))
    return wpath


def _run_jobs(jobs: list, procs: int, progress) -> list[dict]:
    """Every job through :func:`_job`, in ``procs`` forked worker processes (or here for one), reporting
    ``progress(done, total)``; the results in completion order."""
    done: list[dict] = []
    if procs > 1 and len(jobs) > 1:
        with multiprocessing.get_context("fork").Pool(procs) as pool:
            for r in pool.imap_unordered(_job, jobs):
                done.append(r)
                if progress:
                    progress(len(done), len(jobs))
        return done
    for j in jobs:
        done.append(_job(j))
        if progress:
            progress(len(done), len(jobs))
    return done


def aggregate(jobs: Sequence[dict], names: Sequence[str]) -> list[dict]:
    """Per (cell, scheduler): every figure as :func:`mean_ci` over the seeds, in cell order then ``names`` order."""
    by_cell: dict[tuple, list[dict]] = {}
    for j in jobs:
        by_cell.setdefault(tuple(j["cell"].values()), []).append(j)
    out = []
    for key, js in by_cell.items():
        cell = js[0]["cell"]
        # a bound enters only if it was computed on every seed (an exact one may have run out of its budget)
        bounds = {k: [j["bounds"][k] for j in js] for k in ("lp", "exact", "na")
                  if all(j.get("bounds", {}).get(k) is not None for j in js)}
        not_computed = {f"seed {j['seed']}": j["bounds"]["not_computed"] for j in js
                        if j.get("bounds", {}).get("not_computed")}
        for name in names:
            rs = [j["results"][name] for j in js]
            counters = sorted({k for r in rs for k in r["counters"]})
            states = sorted({k for r in rs for k in r["states"]})
            row = {"scheduler": name, **cell, "seeds": [j["seed"] for j in js], "edges": js[0]["edges"],
                   "tasks": mean_ci([r["tasks"] for r in rs]),
                   "utility": mean_ci([r["utility"] for r in rs]),
                   "on_time_rate": mean_ci([r["on_time"] / r["tasks"] for r in rs]),
                   "cloud_cost": mean_ci([r["cloud_cost"] for r in rs]),
                   "edge_cost": mean_ci([r["edge_cost"] for r in rs]),
                   "drops": {s: mean_ci([r["states"].get(s, 0) for r in rs]) for s in states
                             if s not in ("done_on_time", "done_late")},
                   "done_late": mean_ci([r["states"].get("done_late", 0) for r in rs]),
                   "counters": {k: mean_ci([r["counters"].get(k, 0) for r in rs]) for k in counters}}
            if bounds:
                # the tightest bound that holds on every seed: the exact clairvoyant one where computed, else the LP
                hard = "exact" if "exact" in bounds else "lp"
                row["upper_bound_kind"] = hard
                row["upper_bound"] = mean_ci(bounds[hard])
                row["fraction_of_bound"] = mean_ci([r["utility"] / b for r, b in zip(rs, bounds[hard])])
                row["bound_lp"] = mean_ci(bounds["lp"])
                row["fraction_of_lp_bound"] = mean_ci([r["utility"] / b for r, b in zip(rs, bounds["lp"])])
                if "na" in bounds:
                    row["bound_na"] = mean_ci(bounds["na"])
                    row["fraction_of_na_bound"] = mean_ci([r["utility"] / b for r, b in zip(rs, bounds["na"])])
                if not_computed:  # said, with the LP beside it (bound_lp), never left out silently
                    row["bounds_not_computed"] = not_computed
            out.append(row)
    return out


def claims(results: Sequence[dict]) -> list[dict]:
    """Per cell: ``ours`` against the best of :data:`BASELINES` (by mean utility): the ratio of the means, the
    per-seed ratios' CI, whether the 95 % intervals are disjoint, and whether the +10 % target is met; the
    fractions of the bounds; ``headroom`` = the tightest bound on the mean (the non-anticipative one where
    computed, else the hard one) over the best baseline's mean: below 1.10 no online policy can be expected to
    meet the target on those traces (a mean over the seeds, without a CI: indicative, not a proof); and ``vs_evplan``, ours over EVPLAN (our previous scheduler) where both ran."""
    cells: dict[tuple, dict[str, dict]] = {}
    for r in results:
        cells.setdefault((r["load"], r["cloud_sigma"], r["drones_per_edge"], r["scenario"]), {})[r["scheduler"]] = r
    out = []
    for (load, sigma, dpe, sc), rows in cells.items():
        base = [rows[b] for b in BASELINES if b in rows]
        if OURS not in rows or not base:
            continue
        best = max(base, key=lambda r: r["utility"]["mean"])
        ours = rows[OURS]
        ratio = ours["utility"]["mean"] / best["utility"]["mean"] if best["utility"]["mean"] else math.inf
        lo = ours["utility"]["mean"] - ours["utility"]["ci95"]
        hi = best["utility"]["mean"] + best["utility"]["ci95"]
        per_seed = [a / b for a, b in zip(ours["utility"]["per_seed"], best["utility"]["per_seed"]) if b]
        out.append({"load": load, "cloud_sigma": sigma, "drones_per_edge": dpe, "scenario": sc,
                    "best_baseline": best["scheduler"], "ratio": ratio, "ratio_ci": mean_ci(per_seed),
                    "disjoint_ci": lo > hi, "meets_10pct": ratio >= 1.10 and lo > hi,
                    "not_worse": ours["utility"]["mean"] + ours["utility"]["ci95"] >= best["utility"]["mean"],
                    "best_fraction_of_bound": best.get("fraction_of_bound", {}).get("mean"),
                    "ours_fraction_of_bound": ours.get("fraction_of_bound", {}).get("mean"),
                    "best_fraction_of_na_bound": best.get("fraction_of_na_bound", {}).get("mean"),
                    "ours_fraction_of_na_bound": ours.get("fraction_of_na_bound", {}).get("mean"),
                    "headroom": (ours.get("bound_na") or ours.get("upper_bound") or {"mean": math.nan})["mean"]
                    / best["utility"]["mean"] if best["utility"]["mean"] else math.inf,
                    "vs_evplan": ours["utility"]["mean"] / rows["EVPLAN"]["utility"]["mean"]
                    if "EVPLAN" in rows and OURS != "EVPLAN" and rows["EVPLAN"]["utility"]["mean"] else None})
    return out


def _pm(x: dict, scale: float = 1.0, fmt: str = "{:.0f}") -> str:
    return f"{fmt.format(x['mean'] * scale)} ± {fmt.format(x['ci95'] * scale)}"


def format_sweep(res: dict) -> str:
    """The sweep as text: per cell, each scheduler's utility ± CI, on-time rate, fraction of the bound, cloud
    cost, drops and the counters that explain behaviour; then the claim per cell."""
    cfg = res["config"]
    lines = [f"aerodaas bench schedulers --harness: trace {cfg.get('trace_label', 'periodic')}, seeds {cfg['seeds']}, {cfg['duration_s']:g} s, "
             f"{cfg['drones'] or str(cfg['edges_per_run']) + ' edges x drones/edge'} drones; mean ± 95 % CI "
             f"(Student t); {res['wall_s']:.0f} s wall, {res['cpu_s']:.0f} s CPU, {cfg['processes']} process(es)"]
    head = ("scheduler", "utility", "on-time %", "of bound", "of n-a", "cloud cost", "late", "drops t/c/e",
            "steals ok/tried", "jit rel/late-drop", "cloud late(held)", "cloud conc mean/peak")
    cur = None
    rows: list[tuple] = []

    def flush():
        if rows:
            widths = [max(len(x) for x in col) for col in zip(head, *rows)]
            for row in (head, *rows):
                lines.append("  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths))))
            rows.clear()

    for r in res["results"]:
        key = (r["load"], r["cloud_sigma"], r["drones_per_edge"], r["scenario"])
        if key != cur:
            flush()
            cur = key
            b = r.get("upper_bound")
            bs = "" if not b else (f"  (bounds: LP {_pm(r['bound_lp'])}" +
                                   (f", exact {_pm(r['upper_bound'])}" if r["upper_bound_kind"] == "exact" else "") +
                                   (f", non-anticipative {_pm(r['bound_na'])}" if "bound_na" in r else "") +
                                   (f"; not computed: {r['bounds_not_computed']}" if r.get("bounds_not_computed")
                                    else "") + ")")
            lines += ["", f"{r['load']}  cloud sigma {r['cloud_sigma']:g}  {r['drones_per_edge']} drones/edge  network "
                          f"{r['scenario']}" + bs]
        c = {k: v["mean"] for k, v in r["counters"].items()}
        d = {k: v["mean"] for k, v in r["drops"].items()}
        steals_tried = c.get("steal_attempts_idle", 0) + c.get("steal_attempts_busy", 0)
        rows.append((r["scheduler"], _pm(r["utility"]), _pm(r["on_time_rate"], 100, "{:.1f}"),
                     _pm(r["fraction_of_bound"], 1, "{:.3f}") if "fraction_of_bound" in r else "-",
                     f"{r['fraction_of_na_bound']['mean']:.3f}" if "fraction_of_na_bound" in r else "-",
                     f"{r['cloud_cost']['mean']:.0f}", f"{r['done_late']['mean']:.0f}",
                     f"{d.get('dropped_time', 0):.0f}/{d.get('dropped_cost', 0):.0f}/{d.get('expired_edge', 0):.0f}",
                     f"{c.get('steals', 0):.0f}/{steals_tried:.0f}",
                     f"{c.get('jit_released', 0) + c.get('released_to_cloud', 0):.0f}/{c.get('jit_dropped_past_trigger', 0):.0f}",
                     f"{c.get('cloud_done_late', 0):.0f}({c.get('cloud_done_late_after_hold', 0):.0f})",
                     f"{c.get('cloud_mean_concurrency', 0):.1f}/{c.get('cloud_peak_concurrency_per_edge', 0):.0f}"))
    flush()
    if res.get("claims"):
        lines += ["", f"{OURS} vs the best of {', '.join(BASELINES)} (ratio of means; per-seed ratio ± CI; "
                      "95 % CIs disjoint; fractions of the tightest per-seed bound; headroom = tightest bound on "
                      "the mean / best baseline, < 1.10: +10 % is out of reach in expectation)"]
        for c in res["claims"]:
            lines.append(f"  {c['load']:6} σ {c['cloud_sigma']:<4g} {c['drones_per_edge']}/edge {c['scenario']:5} "
                         f"best {c['best_baseline']:6} x{c['ratio']:.3f} ({_pm(c['ratio_ci'], 1, '{:.3f}')}) "
                         f"disjoint {'yes' if c['disjoint_ci'] else 'no '} +10% {'MET' if c['meets_10pct'] else 'not met'}"
                         + (f"  bound fractions {c['best_fraction_of_bound']:.3f} -> {c['ours_fraction_of_bound']:.3f}"
                            f"  headroom x{c['headroom']:.3f}" if c["best_fraction_of_bound"] is not None else "")
                         + (f"  vs EVPLAN x{c['vs_evplan']:.3f}" if c.get("vs_evplan") else ""))
    return "\n".join(lines)


def markdown_tables(res: dict, schedulers: Sequence[str] = ("E+C", "DEM", "DEMS", "DEMS-A", "GEMS", "EVPLAN",
                                                           OURS)) -> str:
    """The sweep as Markdown (the tables of docs/results/schedulers.md): per load and scenario, one row per
    (sigma, drones per edge), one cell per scheduler: utility mean ± CI in thousands, on-time %, fraction of the
    tightest per-seed upper bound (exact where computed, else LP); the bounds' means in their own columns."""
    rows = [r for r in res["results"] if r["scheduler"] in schedulers]
    out = []
    for load, sc in dict.fromkeys((r["load"], r["scenario"]) for r in rows):
        sel = [r for r in rows if (r["load"], r["scenario"]) == (load, sc)]
        exact = any(r.get("upper_bound_kind") == "exact" for r in sel)
        na = any("bound_na" in r for r in sel)
        bcols = ["LP bound (k)"] + (["exact bound (k)"] if exact else []) + (["n-a bound (k)"] if na else [])
        kind = "the exact bound" if exact else "the LP bound"
        out += ["", f"**{load}, network {sc}** — utility (k) ± 95 % CI / on-time % / fraction of {kind}", "",
                "| σ | drones/edge | " + " | ".join(bcols) + " | " + " | ".join(schedulers) + " |",
                "|---|---|" + "---|" * (len(bcols) + len(schedulers))]
        cells = dict.fromkeys((r["cloud_sigma"], r["drones_per_edge"]) for r in sel)
        for sigma, dpe in cells:
            got = {r["scheduler"]: r for r in sel if (r["cloud_sigma"], r["drones_per_edge"]) == (sigma, dpe)}
            r0 = next(iter(got.values()))
            bvals = [r0.get("bound_lp")] + ([r0.get("upper_bound")] if exact else []) + ([r0.get("bound_na")] if na else [])
            cols = []
            for name in schedulers:
                r = got.get(name)
                if r is None:
                    cols.append("")
                    continue
                f = r.get("fraction_of_bound", {}).get("mean")
                cols.append(f"{r['utility']['mean'] / 1e3:.1f} ± {r['utility']['ci95'] / 1e3:.1f} / "
                            f"{100 * r['on_time_rate']['mean']:.0f}" + (f" / {f:.3f}" if f is not None else ""))
            out.append(f"| {sigma:g} | {dpe} | " + " | ".join(f"{b['mean'] / 1e3:.1f}" if b else "-" for b in bvals)
                       + " | " + " | ".join(cols) + " |")
    return "\n".join(out)
