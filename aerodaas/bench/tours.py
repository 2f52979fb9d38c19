"""``aerodaas bench tours``: tour quality and planning time of the trajectory schedulers.

Every scheduler orders the same seeded random instances as an OPEN path from the drone's position (the
objective of :meth:`TrajectoryScheduler.tour_length`, 3-D Euclidean metres, no return). Each tour is compared
with a reference:

* ``"exact"`` (n <= ``exact_max``, default 12): the optimum by the Held–Karp dynamic programme
  (M. Held & R. M. Karp, "A dynamic programming approach to sequencing problems", J. SIAM 10, 1962), adapted
  to an open path with a fixed first node and a free last node — :func:`held_karp_open_path`;
* ``"lower_bound"`` (larger n): the Held–Karp 1-tree bound with subgradient ascent (M. Held & R. M. Karp,
  "The traveling-salesman problem and minimum spanning trees", Operations Research 18, 1970; Part II,
  Math. Programming 1, 1971) on the equivalent closed tour through a dummy node — :func:`open_path_lower_bound`.
  A proven bound, so ``ratio_to_reference`` is an UPPER bound on the optimality gap there.

Instances: ``n`` waypoints uniform in a 1 km x 1 km square centred on the drone's home (x, y in [-500, 500] m),
altitude uniform in [10, 60] m; the drone starts at home, (0, 0, 0). Planning time is one
``scheduler.order(waypoints, start)`` call (waypoint objects in, ordered waypoints out), several repeats per
instance after a warm-up: ``plan_ms`` is wall time, ``plan_cpu_ms`` the planning thread's CPU time (robust to
other load on the machine).

Also the paper's disaster-survey case (:func:`disaster_survey`): a 4-waypoint pre-planned survey of a
10 m x 10 m square, plus 3 waypoints injected over a 10 m x 20 m area once the drone has reached the first
survey waypoint, re-planned from there — the distance each scheduler saves over flying in the given order.
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from typing import Any, Sequence

import numpy as np

from aerodaas.bench.machine import machine_info
from aerodaas.bench.options import TOUR_SIZES
from aerodaas.bench.output import print_report
from aerodaas.model.types import AeroNavigation, NavigationType, SchedulingType, Waypoint
from aerodaas.schedulers import NearestNeighborScheduler, TrajectoryScheduler, TwoOptScheduler
from aerodaas.schedulers.two_opt import held_karp_open_path  # the exact reference (re-exported here)
from aerodaas.schedulers.two_opt import node_cost_matrix

AREA_M = 1000.0
ALT_RANGE_M = (10.0, 60.0)
DEFAULT_SIZES = TOUR_SIZES
EXACT_MAX = 12

# disaster survey (paper §6.1; the same geometry as apps/disaster_survey.py and its `aerodaas inject` example):
# all waypoints at SURVEY_Z_M metres above home (the app's take-off altitude); the drone starts at home on the ground
SURVEY_Z_M = 2.0
SURVEY_START = (0.0, 0.0, 0.0)
SURVEY_PREPLANNED = [(0.0, 0.0), (0.0, 10.0), (10.0, 10.0), (10.0, 0.0)]  # 10 m x 10 m square, given order
SURVEY_INJECTED = [(5.0, 20.0), (0.0, 15.0), (10.0, 15.0)]  # extend the area to 10 m x 20 m, injection order


# ---------------------------------------------------------------------------------------------- references
def _prim(W) -> tuple[float, Any]:
    """Minimum spanning tree of the dense symmetric weight matrix ``W`` (Prim, O(N²)). Returns (cost, degrees)."""
    N = W.shape[0]
    in_tree = np.zeros(N, dtype=bool)
    in_tree[0] = True
    dist = W[0].copy()
    parent = np.zeros(N, dtype=np.int64)
    deg = np.zeros(N, dtype=np.int64)
    total = 0.0
    dist[0] = np.inf
    for _ in range(N - 1):
        v = int(np.argmin(dist))
        total += float(dist[v])
        deg[v] += 1
        deg[parent[v]] += 1
        in_tree[v] = True
        closer = (W[v] < dist) & ~in_tree
        dist = np.where(closer, W[v], dist)
        parent = np.where(closer, v, parent)
        dist[v] = np.inf
        dist[in_tree] = np.inf
    return total, deg


def open_path_lower_bound(D, upper: float, max_iter: int = 400) -> float:
    """A proven lower bound (metres) on the shortest open path from node 0 over the SYMMETRIC matrix ``D``.

    Held–Karp (1970) 1-tree bound adapted to an open path with a fixed start: add a dummy node ``e`` joined to
    the start and, at cost 0, to whichever node ends the path; every such path is then a tour through ``e``. A
    1-tree = a minimum spanning tree on the real nodes plus ``e``'s two edges (to the start, and to the node of
    least penalty). With node penalties ``pi`` the value ``MST(D + pi_u + pi_v) + pi_start + min pi - 2 sum pi``
    is <= every tour, so <= the optimum, for ANY ``pi``; subgradient ascent (g = degree - 2, Polyak step
    towards ``upper``, the length of a known path, halving the step after 20 iterations without progress)
    pushes it up. Returns the best value seen."""
    D = np.asarray(D, dtype=float)
    N = D.shape[0]
    if N <= 1:
        return 0.0
    if N == 2:
        return float(D[0, 1])
    pi = np.zeros(N)
    best = -math.inf
    lam, stall = 2.0, 0
    for _ in range(max_iter):
        W = D + pi[:, None] + pi[None, :]
        tree, deg = _prim(W)
        x = int(np.argmin(pi[1:])) + 1
        value = tree + pi[0] + pi[x] - 2.0 * float(pi.sum())
        if value > best + 1e-9:
            best, stall = value, 0
        else:
            stall += 1
        g = deg.astype(float) - 2.0
        g[0] += 1.0
        g[x] += 1.0
        gg = float(g @ g)
        if gg == 0.0:  # the 1-tree is a Hamiltonian path: the bound is the optimum
            break
        if stall >= 20:
            lam, stall = lam / 2.0, 0
            if lam < 1e-4:
                break
        pi = pi + lam * max(upper - value, 1e-9 * max(upper, 1.0)) / gg * g
    return float(best)


# ---------------------------------------------------------------------------------------------- instances
def random_instance(rng, n: int) -> list:
    """``n`` waypoints uniform in the 1 km x 1 km square centred on home, altitude uniform in [10, 60] m."""
    xy = rng.uniform(-AREA_M / 2.0, AREA_M / 2.0, size=(n, 2))
    z = rng.uniform(*ALT_RANGE_M, size=n)
    return [Waypoint(id=f"w{i}", x=float(xy[i, 0]), y=float(xy[i, 1]), z=float(z[i])) for i in range(n)]


def default_schedulers() -> dict:
    """The schedulers compared, name -> zero-argument factory: the paper's nearest neighbour and the
    2-opt/Or-opt plug-in."""
    return {"nearest_neighbor": NearestNeighborScheduler, "two_opt": TwoOptScheduler}


def _matrix(waypoints: Sequence, start: Sequence[float]):
    pts = [(w.x, w.y, w.z) for w in waypoints]
    return node_cost_matrix(pts, pts, start)


def _stats(values: list[float], digits: int = 4) -> dict:
    return {"median": round(statistics.median(values), digits), "max": round(max(values), digits)}


def run_tours(sizes: Sequence[int] = DEFAULT_SIZES, instances: int = 5, seed: int = 0, repeats: int = 3,
              exact_max: int = EXACT_MAX, schedulers: dict | None = None) -> dict:
    """Run the benchmark; returns the JSON-ready result (see the module doc and ``aerodaas bench tours``).

    ``schedulers`` maps a name to a zero-argument factory of a TrajectoryScheduler (default: nearest_neighbor
    and two_opt)."""
    if instances < 1 or repeats < 1:
        raise ValueError("instances and repeats must be >= 1")
    if any(n < 1 for n in sizes):
        raise ValueError(f"sizes must be >= 1, got {list(sizes)}")
    factories = schedulers or default_schedulers()
    scheds = {name: f() for name, f in factories.items()}
    start = (0.0, 0.0, 0.0)
    warm = random_instance(np.random.default_rng(seed + 10_000), 30)
    for s in scheds.values():  # warm-up: imports, caches
        s.order(list(warm), start)
    results, bound_checks = [], []
    for n in sizes:
        rng = np.random.default_rng([seed, n])
        per: dict[str, dict[str, list]] = {name: {"ratio": [], "ms": [], "cpu": [], "len": []} for name in scheds}
        tight: list[float] = []
        exact = n <= exact_max
        for _ in range(instances):
            wps = random_instance(rng, n)
            lengths = {}
            for name, s in scheds.items():
                for r in range(repeats):
                    c0, t0 = time.thread_time(), time.perf_counter()
                    tour = s.order(list(wps), start)
                    per[name]["ms"].append((time.perf_counter() - t0) * 1e3)
                    per[name]["cpu"].append((time.thread_time() - c0) * 1e3)
                    if r == 0:
                        if sorted(w.id for w in tour) != sorted(w.id for w in wps):
                            raise RuntimeError(f"scheduler {name!r} did not return a permutation of its input")
                        lengths[name] = TrajectoryScheduler.tour_length(tour, start)
            D = _matrix(wps, start)
            if exact:
                ref, _ = held_karp_open_path(D)
                lb = open_path_lower_bound(D, upper=ref)
                tight.append(lb / ref if ref > 0 else 1.0)
            else:
                ref = open_path_lower_bound(D, upper=min(lengths.values()))
            for name in scheds:
                per[name]["len"].append(lengths[name])
                per[name]["ratio"].append(lengths[name] / ref if ref > 0 else 1.0)
        for name in scheds:
            results.append({
                "size": n, "scheduler": name, "instances": instances,
                "ratio_to_reference": _stats(per[name]["ratio"]),
                "reference": "exact" if exact else "lower_bound",
                "plan_ms": _stats(per[name]["ms"], 3),
                "plan_cpu_ms": _stats(per[name]["cpu"], 3),
                "mean_length_m": round(statistics.fmean(per[name]["len"]), 2),
            })
        if exact:
            bound_checks.append({"size": n, "instances": instances,
                                 "lower_bound_over_optimum": {"median": round(statistics.median(tight), 4),
                                                              "min": round(min(tight), 4),
                                                              "max": round(max(tight), 4)}})
    return {
        "benchmark": "tours",
        "machine": machine_info(),
        "config": {"seed": seed, "sizes": list(sizes), "instances": instances, "repeats": repeats,
                   "exact_max": exact_max, "area_m": [AREA_M, AREA_M], "area_centre": [0.0, 0.0],
                   "altitude_m": list(ALT_RANGE_M), "start": list(start), "metric": "3-D Euclidean, open path",
                   "schedulers": list(scheds)},
        "reference_methods": {
            "exact": "Held-Karp dynamic programme (Held & Karp 1962), open path from the start",
            "lower_bound": "Held-Karp 1-tree bound with subgradient ascent (Held & Karp 1970), open path via a "
                           "dummy node; ratio_to_reference is then an upper bound on the optimality gap",
        },
        "results": results,
        "lower_bound_check": bound_checks,
        "disaster_survey": disaster_survey(factories),
    }


def disaster_survey(schedulers: dict | None = None) -> dict:
    """The paper's disaster-survey case, flown through the scheduler API for each scheduler.

    The drone starts at home (0, 0, 0); the survey is the 10 m x 10 m square's corners at ``SURVEY_Z_M`` m; once it
    has reached the first survey waypoint, 3 waypoints over the 10 m x 20 m area are added (UNORDERED, same
    priority) and the rest of the mission is re-planned from that position. Two variants: the survey itself
    UNORDERED (everything left may be re-ordered), or ORDERED (the survey's remaining waypoints stay one fixed
    run, the injected ones are free). Distances in metres; "given order" = survey in its given order, then the
    injected waypoints in injection order."""
    factories = schedulers or default_schedulers()
    z = SURVEY_Z_M

    def survey():
        return [Waypoint(id=f"s{i + 1}", x=x, y=y, z=z) for i, (x, y) in enumerate(SURVEY_PREPLANNED)]

    def injected():
        return [Waypoint(id=f"i{i + 1}", x=x, y=y, z=z) for i, (x, y) in enumerate(SURVEY_INJECTED)]

    def fly(s: TrajectoryScheduler, survey_type: SchedulingType) -> tuple[float, list[str]]:
        s.start = SURVEY_START
        s.generate_navigation(AeroNavigation(NavigationType.DISTANCE_DRIVEN, survey(), survey_type))
        pos, flown, visited = SURVEY_START, 0.0, []

        def step() -> None:
            nonlocal pos, flown
            _, w = s.current(0.0)
            flown += math.dist(pos, (w.x, w.y, w.z))
            pos = (w.x, w.y, w.z)
            visited.append(w.id)
            s.complete(w.id)

        step()  # reach the first survey waypoint, then the analytics inject three more
        s.add_navigation(AeroNavigation(NavigationType.ANALYTICS_DRIVEN, injected(), SchedulingType.UNORDERED),
                         priority=2, position=pos)
        while s.current(0.0) is not None:
            step()
        return flown, visited

    given = survey() + injected()
    given_m = TrajectoryScheduler.tour_length(given, SURVEY_START)
    first = survey()[0]
    p1 = (first.x, first.y, first.z)
    leg1 = math.dist(SURVEY_START, p1)
    scenarios = []
    for survey_type in (SchedulingType.UNORDERED, SchedulingType.ORDERED):
        rest = survey()[1:]
        if survey_type == SchedulingType.ORDERED:
            nodes = [rest] + [[w] for w in injected()]
        else:
            nodes = [[w] for w in rest + injected()]
        entries = [(n[0].x, n[0].y, n[0].z) for n in nodes]
        exits = [(n[-1].x, n[-1].y, n[-1].z) for n in nodes]
        inner = sum(TrajectoryScheduler.tour_length(n[1:], (n[0].x, n[0].y, n[0].z)) for n in nodes)
        opt, _ = held_karp_open_path(node_cost_matrix(entries, exits, p1))
        entry: dict[str, Any] = {"survey_scheduling": survey_type.value, "given_order_m": round(given_m, 3),
                                 "optimal_replan_m": round(leg1 + inner + opt, 3), "schedulers": {}}
        for name, factory in factories.items():
            flown, order = fly(factory(), survey_type)
            entry["schedulers"][name] = {"distance_m": round(flown, 3), "saved_m": round(given_m - flown, 3),
                                         "saved_pct": round(100.0 * (given_m - flown) / given_m, 2),
                                         "order": order}
        scenarios.append(entry)
    return {
        "altitude_m": z, "start": list(SURVEY_START),
        "survey": [[x, y, z] for x, y in SURVEY_PREPLANNED], "survey_area_m": [10.0, 10.0],
        "injected": [[x, y, z] for x, y in SURVEY_INJECTED], "injected_area_m": [10.0, 20.0],
        "injected_after": "s1",
        "given_order": [w.id for w in given],
        "scenarios": scenarios,
    }


# ---------------------------------------------------------------------------------------------- CLI
def main(args: argparse.Namespace) -> int:
    res = run_tours(sizes=args.sizes, instances=args.instances, seed=args.seed, repeats=args.repeats)
    text = json.dumps(res, indent=2)
    if args.out:
        try:
            with open(args.out, "w", encoding="utf-8") as f:
                f.write(text + "\n")
        except OSError as e:
            print(f"aerodaas bench tours: cannot write {args.out!r}: {e}", file=sys.stderr)
            return 2

    print_report(text if args.json else format_table(res))
    return 0


def format_table(res: dict) -> str:
    """Human-readable summary of a :func:`run_tours` result (plain text)."""
    m, cfg = res["machine"], res["config"]
    lines = [f"aerodaas bench tours: {cfg['instances']} instances per size, seed {cfg['seed']}, "
             f"{m['cpu_count']} CPUs, Python {m['python']} ({m['platform']})",
             "ratio = tour length / reference (exact optimum, or a proven lower bound: then an upper bound on the gap)",
             ""]
    head = ("n", "scheduler", "reference", "ratio med", "ratio max", "plan ms med", "plan ms max", "mean length m")
    rows = [(str(r["size"]), r["scheduler"], r["reference"], f"{r['ratio_to_reference']['median']:.4f}",
             f"{r['ratio_to_reference']['max']:.4f}", f"{r['plan_ms']['median']:.2f}", f"{r['plan_ms']['max']:.2f}",
             f"{r['mean_length_m']:.1f}") for r in res["results"]]
    widths = [max(len(x) for x in col) for col in zip(head, *rows)]
    left = {1, 2}
    for row in (head, *rows):
        lines.append("  ".join(c.ljust(w) if i in left else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths))))
    for c in res["lower_bound_check"]:
        b = c["lower_bound_over_optimum"]
        lines.append(f"lower bound / exact optimum at n={c['size']}: median {b['median']:.4f}, min {b['min']:.4f}")
    ds = res["disaster_survey"]
    lines += ["", f"disaster survey (all waypoints at z = {ds['altitude_m']} m; start {tuple(ds['start'])}; "
                  f"{len(ds['injected'])} waypoints injected after reaching {ds['injected_after']}):"]
    for sc in ds["scenarios"]:
        lines.append(f"  survey {sc['survey_scheduling']}: given order {sc['given_order_m']:.2f} m, "
                     f"optimal re-plan {sc['optimal_replan_m']:.2f} m")
        for name, v in sc["schedulers"].items():
            lines.append(f"    {name:<18} {v['distance_m']:7.2f} m  saves {v['saved_m']:6.2f} m "
                         f"({v['saved_pct']:.1f}%)  order {' '.join(v['order'])}")
    return "\n".join(lines)
