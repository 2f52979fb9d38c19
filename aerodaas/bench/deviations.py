"""The measured size of our deviations from the reference DEMS code (docs/analytics-scheduler-rules.md, "Deviations from the reference").

Each deviation that can be switched is run both ways on the same traces and draws (the policy harness,
:mod:`aerodaas.bench.harness`): per seed, the relative utility change ``variant / as-shipped - 1``, reported as mean
± 95 % CI (Student t) over the seeds, for HEAVY at each (cloud sigma, drones per edge). Run with
``python -m aerodaas.bench.deviations [--seeds N] [--duration S] [--json]``. The variants are defined here and
not registered: they exist to be measured.
"""
from __future__ import annotations

import argparse
import itertools
import json
import sys
from typing import Callable

from aerodaas.bench.harness import fleet_tasks, run_fleet
from aerodaas.bench.workload import default_workload_path, make_trace
from aerodaas.bench.sweep import mean_ci, scenario_specs
from aerodaas.schedulers.analytics_base import AnalyticsScheduler, Workload
from aerodaas.schedulers.analytics_dems import Dem, Dems, Gems
from aerodaas.schedulers.dispatch.emulation import Jitter

__all__ = ["VARIANTS", "measure"]


class _GemsIgnoringRefusals(Gems):
    """GEMS as the code counts: a task refused by the cloud re-check never reaches PostProcessing (deviation 6)."""

    def on_cloud_done(self, task, now_ms, latency_ms):
        if task.tier is None or task.state.value == "dropped_time":
            return self._settle([], now_ms)
        return super().on_cloud_done(task, now_ms, latency_ms)


class _GemsNoIdleSteal(Gems):
    """GEMS as the code's algorithm 35 in one of its three differences: no stealing when the edge queue is empty."""

    steal_when_idle = False


def _slack_132(cls: type) -> Callable[[Workload], AnalyticsScheduler]:
    def make(w: Workload) -> AnalyticsScheduler:
        p = cls(w)
        p.steal_slack_ms = 132.0  # the code's hard-coded threshold (deviation 5)
        return p
    return make


#: deviation number -> (what the variant does, the as-shipped policy, the variant's factory)
VARIANTS: dict[str, tuple[str, str, Callable[[Workload], AnalyticsScheduler]]] = {
    "2 (DEM)": ("our earlier full eviction scan instead of the reference's", "DEM",
                lambda w: Dem(w, eviction_scan="full")),
    "2 (DEMS)": ("our earlier full eviction scan instead of the reference's", "DEMS", lambda w: Dems(w, eviction_scan="full")),
    "2 (GEMS)": ("our earlier full eviction scan instead of the reference's", "GEMS", lambda w: Gems(w, eviction_scan="full")),
    "5 (DEMS)": ("steal slack threshold 132 ms (the code) instead of the shortest edge time, 142 ms", "DEMS",
                 _slack_132(Dems)),
    "6 (GEMS)": ("refused cloud tasks not counted by the gatekeeper (the code)", "GEMS", _GemsIgnoringRefusals),
    "7 (GEMS)": ("no work stealing when the edge queue is empty (the code's algorithm 35)", "GEMS", _GemsNoIdleSteal),
}


def measure(*, seeds: int = 5, duration_s: float = 60.0, edges: int = 4, sigmas=(0.0, 0.1),
            drones_per_edge=(2, 3), scenarios=("none", "step"), load: str = "HEAVY",
            workload_path: str | None = None) -> list[dict]:
    """Run every variant against its as-shipped policy; one row per (deviation, sigma, drones per edge) with the
    relative change of utility (``delta``, mean ± CI over seeds) and both utilities' means."""
    w = Workload.from_file(workload_path or default_workload_path(), load)
    ej = Jitter("lognormal", 0.05)
    rows = []
    for sigma, sc, dpe in itertools.product(sigmas, scenarios, drones_per_edge):
        cj = Jitter("lognormal", sigma)
        net = scenario_specs(sc, duration_s)
        traces = {s: fleet_tasks(make_trace(w, edges * dpe, duration_s, s, dpe), w) for s in range(seeds)}
        base = {}
        for dev, (what, name, factory) in VARIANTS.items():
            if name not in base:
                base[name] = [run_fleet(name, w, traces[s], seed=s, edge_jitter=ej, cloud_jitter=cj,
                                        network_specs=net)["utility"] for s in range(seeds)]
            var = [run_fleet(name, w, traces[s], seed=s, edge_jitter=ej, cloud_jitter=cj, network_specs=net,
                             factory=factory)["utility"] for s in range(seeds)]
            rows.append({"deviation": dev, "variant": what, "policy": name, "load": load, "cloud_sigma": sigma,
                         "scenario": sc, "drones_per_edge": dpe, "seeds": list(range(seeds)), "duration_s": duration_s,
                         "edges": edges, "shipped_utility": mean_ci(base[name]),
                         "variant_utility": mean_ci(var),
                         "delta": mean_ci([v / b - 1.0 for v, b in zip(var, base[name])])})
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    rows = measure(seeds=a.seeds, duration_s=a.duration)
    if a.json:
        print(json.dumps(rows, indent=2))
        return 0
    for r in rows:
        d = r["delta"]
        print(f"deviation {r['deviation']:9} σ {r['cloud_sigma']:<4g} {r['scenario']:4} {r['drones_per_edge']}/edge: variant "
              f"{100 * d['mean']:+.1f} % ± {100 * d['ci95']:.1f} ({r['variant']})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
