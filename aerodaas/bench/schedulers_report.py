"""The output side of ``aerodaas bench schedulers``: per-seed runs summarised as mean ± 95 % CI, the emulation's
validity, the text table, the comparison figure, and the check of a runtime result against the policy harness on
the same traces and draws."""
from __future__ import annotations

import math
import os
from typing import Sequence

from aerodaas.bench.harness import fleet_tasks, run_fleet
from aerodaas.bench.sweep import mean_ci
from aerodaas.bench.workload import make_trace, scenario_specs
from aerodaas.bench.traces import TraceSpec
from aerodaas.schedulers.analytics_base import Workload
from aerodaas.schedulers.dispatch.emulation import Jitter

__all__ = ["summarize_runs", "format_table", "write_plot", "compare_with_harness"]


def _emulation_p99(row: dict) -> float:
    """The worst timing-error p99 of one run (ms): arrival lateness, edge hold error, |cloud round-trip error|,
    poll lateness."""
    t = row["timing_ms"]
    return max(abs(t[k]["p99"]) for k in ("arrival_lateness", "edge_hold_error", "cloud_rtt_error", "poll_lateness")
               if t[k]["n"]) if any(t[k]["n"] for k in t) else 0.0


def summarize_runs(runs: Sequence[dict]) -> list[dict]:
    """Per (load, cloud sigma, scenario, scheduler): every figure as mean ± 95 % CI over the seeds
    (:func:`aerodaas.bench.sweep.mean_ci`), the counters' means, and the emulation's validity (valid only if every
    seed's run was)."""
    groups: dict[tuple, list[dict]] = {}
    for r in runs:
        groups.setdefault((r["load"], r.get("cloud_sigma"), r.get("scenario", "none"), r["scheduler"]), []).append(r)
    out = []
    for (load, sigma, sc, name), rs in groups.items():
        counters = sorted({k for r in rs for k in r.get("counters", {})})
        states = sorted({k for r in rs for k in r["states"]})
        out.append({
            "scheduler": name, "load": load, "cloud_sigma": sigma, "drones_per_edge": rs[0]["drones_per_edge"],
            "scenario": sc, "drones": rs[0]["drones"], "edges": rs[0]["edges"], "seeds": [r["seed"] for r in rs],
            "utility": mean_ci([r["utility"] for r in rs]), "on_time_rate": mean_ci([r["on_time_rate"] for r in rs]),
            "cloud_cost": mean_ci([r["cloud_cost"] for r in rs]), "edge_cost": mean_ci([r["edge_cost"] for r in rs]),
            "drops": {k: mean_ci([r["states"].get(k, 0) for r in rs]) for k in states
                      if k not in ("done_on_time", "done_late")},
            "done_late": mean_ci([r["states"].get("done_late", 0) for r in rs]),
            "counters": {k: mean_ci([r.get("counters", {}).get(k, 0) for r in rs]) for k in counters},
            "emulation_p99_ms": [r["emulation_p99_ms"] for r in rs],
            "emulation_valid": all(r["emulation_valid"] for r in rs),
        })
    return out



def format_table(res: dict) -> str:
    """Human-readable summary of a :func:`run_schedulers` result: per load, sigma and scenario, each scheduler's
    figures as mean ± 95 % CI over the seeds, the counters, and whether the emulation was valid."""
    cfg, m = res["config"], res["machine"]
    lines = [f"aerodaas bench schedulers: {cfg['drones']} drones ({cfg['drones_per_edge']} per edge, {cfg['edges']} "
             f"edges), {cfg['duration_s']:g} s at {cfg['fps']:g} fps, seeds {res['seeds']}, {m['cpu_count']} CPUs, "
             f"load average {m['load_avg_1min']} at the start; mean ± 95 % CI (Student t); a run is valid if its "
             f"emulation error p99 <= {cfg['emulation_bound_ms']:g} ms"]
    head = ("scheduler", "utility", "on-time %", "cloud cost", "drops t/c/e", "late", "steals ok/tried",
            "cloud late(held)", "cloud conc", "emul p99 ms", "valid")
    cur, rows = None, []

    def flush():
        if rows:
            widths = [max(len(x) for x in col) for col in zip(head, *rows)]
            for row in (head, *rows):
                lines.append("  ".join(c.ljust(w) if i == 0 else c.rjust(w)
                                       for i, (c, w) in enumerate(zip(row, widths))))
            rows.clear()

    for r in res["results"]:
        key = (r["load"], r["cloud_sigma"], r["scenario"])
        if key != cur:
            flush()
            cur = key
            lines += ["", f"{r['load']}  cloud sigma {r['cloud_sigma'] if r['cloud_sigma'] is not None else cfg['cloud_jitter']}"
                          f"  network {r['scenario']}"]
        c = {k: v["mean"] for k, v in r["counters"].items()}
        d = {k: v["mean"] for k, v in r["drops"].items()}
        u, o = r["utility"], r["on_time_rate"]
        rows.append((r["scheduler"], f"{u['mean']:.0f} ± {u['ci95']:.0f}",
                     f"{100 * o['mean']:.1f} ± {100 * o['ci95']:.1f}", f"{r['cloud_cost']['mean']:.0f}",
                     f"{d.get('dropped_time', 0):.0f}/{d.get('dropped_cost', 0):.0f}/{d.get('expired_edge', 0):.0f}",
                     f"{r['done_late']['mean']:.0f}",
                     f"{c.get('steals', 0):.0f}/{c.get('steal_attempts_idle', 0) + c.get('steal_attempts_busy', 0):.0f}",
                     f"{c.get('cloud_done_late', 0):.0f}({c.get('cloud_done_late_after_hold', 0):.0f})",
                     f"{c.get('cloud_mean_concurrency', 0):.1f}", "/".join(f"{x:.0f}" for x in r["emulation_p99_ms"]),
                     "yes" if r["emulation_valid"] else "INVALID"))
    flush()
    if "harness_comparison" in res:
        lines += ["", "runtime vs harness (same traces, seeds and draws; harness mean ± 95 % CI):"]
        for h in res["harness_comparison"]:
            lines.append(f"  {h['load']} {h['scheduler']:9} runtime {h['runtime']:.0f} harness {h['harness_mean']:.0f} ± "
                         f"{h['harness_ci95']:.0f}: {'within' if h['within_ci'] else 'OUTSIDE'} the CI"
                         + ("" if h["emulation_valid"] else " (emulation INVALID)"))
    return "\n".join(lines)


def write_plot(res: dict, path: str | os.PathLike) -> None:
    """A comparison figure (PNG): one panel per cell (load, sigma, drones per edge, scenario), utility by scheduler
    as mean with its 95 % CI; the upper bound as a line where known; runs with an invalid emulation hatched and
    labelled INVALID."""
    import matplotlib  # lazy: heavy dependency (matplotlib)

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: heavy dependency (matplotlib)

    cells = list(dict.fromkeys((r["load"], r["cloud_sigma"], r["drones_per_edge"], r["scenario"])
                               for r in res["results"]))
    ncol = min(4, len(cells))
    nrow = math.ceil(len(cells) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(max(6.5, 4.2 * ncol), 3.4 * nrow + 0.5), squeeze=False)
    for ax, cell in zip(axes.flat, cells):
        rs = [r for r in res["results"] if (r["load"], r["cloud_sigma"], r["drones_per_edge"], r["scenario"]) == cell]
        x = range(len(rs))
        valid = [r.get("emulation_valid", True) for r in rs]
        bars = ax.bar(x, [r["utility"]["mean"] for r in rs], yerr=[r["utility"]["ci95"] for r in rs], capsize=3,
                      color=["#264653" if v else "#bbbbbb" for v in valid])
        for b, v in zip(bars, valid):
            if not v:
                b.set_hatch("//")
                ax.text(b.get_x() + b.get_width() / 2, b.get_height(), "INVALID", rotation=90, ha="center",
                        va="bottom", fontsize=7, color="#e76f51")
        if "upper_bound" in rs[0]:
            ax.axhline(rs[0]["upper_bound"]["mean"], color="#e76f51", ls="--", lw=1,
                       label=f"upper bound ({rs[0].get('upper_bound_kind', 'lp')})")
            if "bound_na" in rs[0]:
                ax.axhline(rs[0]["bound_na"]["mean"], color="#2a9d8f", ls=":", lw=1, label="non-anticipative bound")
            ax.legend(fontsize=6, loc="lower right")
        ax.set_xticks(list(x))
        ax.set_xticklabels([r["scheduler"] for r in rs], rotation=40, ha="right", fontsize=7)
        ax.set_title(f"{cell[0]} σ={cell[1]} {cell[2]}/edge {cell[3]}", fontsize=8)
        ax.grid(axis="y", alpha=0.3)
        ax.tick_params(axis="y", labelsize=7)
    for ax in list(axes.flat)[len(cells):]:
        ax.axis("off")
    seeds = res.get("seeds") or res["config"].get("seeds")
    fig.suptitle(f"Analytics schedulers ({res.get('mode', 'runtime')}): total utility, mean ± 95 % CI over seeds "
                 f"{seeds}", fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.4 / (3.4 * nrow + 0.5)))
    fig.savefig(path, dpi=100)
    plt.close(fig)


def compare_with_harness(res: dict, workload_path: str | os.PathLike | None = None) -> list[dict]:
    """For each runtime result, the harness on the same configuration, traces, seeds and draws: whether the
    runtime's mean utility lies within the harness's mean ± 95 % CI (the runtime adds only its emulation error, so
    on a valid emulation the two agree seed by seed)."""
    cfg = res["config"]
    wpath = workload_path or cfg["workload"]
    out = []
    for r in res["results"]:
        w = Workload.from_file(wpath, r["load"])
        cj = Jitter.parse(cfg["cloud_jitter"]) if r["cloud_sigma"] is None else Jitter("lognormal", r["cloud_sigma"])
        specs = list(cfg["network_variability"]) + scenario_specs(r["scenario"], cfg["duration_s"])
        spec = TraceSpec(**cfg["trace"]) if cfg.get("trace") else None
        us = [run_fleet(r["scheduler"], w, fleet_tasks(make_trace(w, cfg["drones"], cfg["duration_s"], sd,
                                                                  cfg["drones_per_edge"], cfg["fps"], spec), w),
                        seed=sd, edge_jitter=Jitter.parse(cfg["edge_jitter"]), cloud_jitter=cj, network_specs=specs,
                        options=cfg["options"])["utility"] for sd in r["seeds"]]
        h = mean_ci(us)
        out.append({"scheduler": r["scheduler"], "load": r["load"], "cloud_sigma": r["cloud_sigma"],
                    "scenario": r["scenario"], "runtime": r["utility"]["mean"], "runtime_ci95": r["utility"]["ci95"],
                    "harness_mean": h["mean"], "harness_ci95": h["ci95"], "harness_per_seed": us,
                    "runtime_per_seed": r["utility"]["per_seed"],
                    "relative_difference": (r["utility"]["mean"] - h["mean"]) / h["mean"] if h["mean"] else None,
                    "within_ci": abs(r["utility"]["mean"] - h["mean"]) <= h["ci95"],
                    "emulation_valid": r["emulation_valid"]})
    return out
