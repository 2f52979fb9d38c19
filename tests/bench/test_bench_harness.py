"""The scheduler benchmark's deterministic side: the harness sweep's CI/sweep output shape and determinism, the
fair-margin estimator option, the behaviour counters, the upper bounds (LP, exact, non-anticipative), the runtime's
emulation-validity marking, and the CLI's ``--harness`` mode. No timing is asserted; every run here is a few
simulated seconds."""
from __future__ import annotations

import itertools
import json
import random

import pytest

from aerodaas.bench.bound import lognormal_on_time_chance, lognormal_slack, utility_upper_bound
from aerodaas.bench.harness import Harness, fleet_tasks, make_trace, run_fleet, run_policy
from aerodaas.bench.workload import make_trace as fleet_trace
from aerodaas.bench.schedulers_report import summarize_runs
from aerodaas.bench.sweep import mean_ci, run_sweep, scenario_specs, t95
from aerodaas.schedulers.dispatch.emulation import Jitter
from aerodaas.schedulers.analytics_base import (AnalyticsTask, TaskState, Workload, filter_options,
                                                make_analytics_scheduler)
from aerodaas.schedulers.analytics_estimators import make_estimator

from tests.conftest import DATA_DIR, needs_workload

WORKLOAD_JSON = DATA_DIR / "workloads" / "ocularone_lambda.json"
JIT = ["DEMS", "DEMS-A", "GEMS", "GAINPLAN", "EVPLAN", "LAPLAN"]


# --------------------------------------------------------------------------------------------- statistics
def test_mean_ci_is_the_student_t_interval_of_the_mean():
    r = mean_ci([1.0, 2.0, 3.0])                       # sd 1, n 3: t(2) = 4.303, half-width 4.303 / sqrt(3)
    assert r["mean"] == 2.0 and r["per_seed"] == [1.0, 2.0, 3.0] and r["n"] == 3
    assert r["ci95"] == pytest.approx(4.303 / 3 ** 0.5)
    assert mean_ci([5.0])["ci95"] == 0.0               # one seed: no interval
    assert t95(4) == pytest.approx(2.776) and t95(1000) == pytest.approx(1.96)
    with pytest.raises(ValueError):
        mean_ci([])


def test_scenarios_are_network_specs():
    assert scenario_specs("none", 120) == []
    assert scenario_specs("step", 120) == ["+200@40-60", "+200@100-120"]
    with pytest.raises(ValueError, match="network scenario"):
        scenario_specs("storm", 60)


# --------------------------------------------------------------------------------------------- the sweep
def _small_sweep(processes: int, **kw) -> dict:
    args = dict(loads=["HEAVY"], sigmas=[0.0, 0.1], drones_per_edge=[2], scenarios=["none"], seeds=[0, 1],
                edges=1, duration_s=8.0, schedulers=["DEM", "DEMS", "DEMS-A", "GEMS", "EVPLAN", "LAPLAN"],
                workload_path=WORKLOAD_JSON, processes=processes)
    args.update(kw)
    return run_sweep(**args)


@needs_workload
def test_harness_sweep_reports_every_figure_as_mean_ci_with_per_seed_values_and_is_deterministic():
    a = _small_sweep(1)
    assert a["mode"] == "harness" and a["config"]["seeds"] == [0, 1]
    assert len(a["results"]) == 2 * 6                  # 2 sigmas x 6 schedulers
    for r in a["results"]:
        for k in ("scheduler", "load", "cloud_sigma", "drones_per_edge", "seeds", "cloud_cost", "drops"):
            assert k in r
        for k in ("utility", "on_time_rate", "fraction_of_bound", "fraction_of_lp_bound", "fraction_of_na_bound"):
            assert set(r[k]) >= {"mean", "ci95", "per_seed"} and len(r[k]["per_seed"]) == 2
            assert r[k]["mean"] == pytest.approx(sum(r[k]["per_seed"]) / 2)
        assert r["upper_bound_kind"] == "exact"        # HEAVY: the exact optimum, below the LP on every seed
        assert all(e <= lp + 1e-6 for e, lp in zip(r["upper_bound"]["per_seed"], r["bound_lp"]["per_seed"]))
        assert all(f <= 1.0 + 1e-9 for f in r["fraction_of_bound"]["per_seed"])  # nobody beats the exact optimum
        assert r["seeds"] == [0, 1] and r["drones_per_edge"] == 2
    assert {(c["cloud_sigma"], c["best_baseline"] in ("DEM", "DEMS", "DEMS-A", "GEMS")) for c in a["claims"]} == \
        {(0.0, True), (0.1, True)}
    b = _small_sweep(2)                                # other process count, same numbers
    strip = lambda res: json.dumps([res["results"], res["claims"]], sort_keys=True)  # noqa: E731
    assert strip(a) == strip(b)


@needs_workload
def test_sweep_refuses_bad_parameters_before_running():
    with pytest.raises(ValueError, match="cloud_sigma"):
        _small_sweep(1, sigmas=[-0.1])
    with pytest.raises(ValueError, match="unknown"):
        _small_sweep(1, schedulers=["NOPE"])
    with pytest.raises(ValueError, match="estimator"):
        _small_sweep(1, options={"estimator": "median"})


# --------------------------------------------------------------------------------------------- estimator option
@pytest.mark.parametrize("spec,after,expected", [
    ("profile", [500.0, 300.0], 200.0),
    ("max:2", [260.0, 230.0, 210.0], 230.0),           # the largest of the last 2
    ("p50:4", [100.0, 300.0, 200.0, 400.0], 200.0),    # nearest-rank median of the last 4
    ("mean:2", [240.0, 260.0], 250.0),                 # window full, drift 50 > 10 ms
])
def test_every_just_in_time_policy_takes_the_same_estimator(spec, after, expected):
    w = Workload.from_dict({"models": {"A": {"edge_ms": 100, "cloud_ms": 200, "benefit": 50, "edge_cost": 1,
                                             "cloud_cost": 10}}, "loads": {"T": {"A": 400}}}, "T")
    for name in JIT:
        pol = make_analytics_scheduler(name, w, **filter_options(name, {"estimator": spec, "eviction_scan": "full"}))
        for i, lat in enumerate(after):
            t = AnalyticsTask(i, "d", "A", 0.0, 10_000.0)
            t.tier, t.start_ms, t.state = "cloud", 0.0, TaskState.DONE_ON_TIME
            pol.on_cloud_done(t, lat, lat)
        got = pol.cloud_estimate_ms("A") if name not in ("EVPLAN", "LAPLAN") else pol.point.value("A")
        assert got == pytest.approx(expected), name
    assert filter_options("EDGE_EDF", {"estimator": "max:2"}) == {}  # edge-only policies have no estimator
    with pytest.raises(ValueError, match="estimator 'p0x'"):
        make_estimator("p0x", w)


# --------------------------------------------------------------------------------------------- counters
@needs_workload
def test_counters_explain_steals_jit_releases_and_cloud_use():
    w = Workload.from_file(WORKLOAD_JSON, "HEAVY")
    trace = make_trace(w, drones=2, duration_s=20, seed=3)
    res = run_policy("DEMS", w, trace, cloud_jitter=Jitter("lognormal", 0.1), seed=3)
    c = res.counters
    tried = c["steal_attempts_idle"] + c["steal_attempts_busy"]
    assert 0 < c["steals"] <= tried
    assert sum(t.notes.get("stolen", False) for t in res.tasks) == c["steals"]
    assert c["cloud_sent"] == len(res.cloud_sends) and c["cloud_peak_concurrency"] >= 1
    late_cloud = [t for t in res.tasks if t.tier == "cloud" and t.state is TaskState.DONE_LATE]
    assert c["cloud_done_late"] == len(late_cloud) and c["cloud_done_late_after_hold"] <= len(late_cloud)
    assert c["jit_released"] >= c["jit_released_after_trigger"]
    assert c["admitted"] + c["rejected"] == len(res.tasks)


@needs_workload
@pytest.mark.parametrize("name", ["DEMS", "LAPLAN"])
def test_a_run_stopped_at_a_time_is_the_full_run_before_it(name):
    """``until_ms``: the log and edge starts before the stop are exactly the full run's, and nothing at or after it
    (the non-anticipation test compares its post-cut runs only before their cut)."""
    w = Workload.from_file(WORKLOAD_JSON, "HEAVY")
    trace = make_trace(w, drones=3, duration_s=8, seed=5, jitter_ms=250.0)

    def run(until_ms=None):
        pol = make_analytics_scheduler(name, w)
        h = Harness(pol, cloud_jitter=Jitter("lognormal", 0.2), edge_jitter=Jitter("lognormal", 0.05), seed=5)
        return h.run([AnalyticsTask(t.task_id, t.drone, t.model, t.arrival_ms, t.deadline_ms) for t in trace],
                     until_ms=until_ms)

    full = run()
    for cut in (1500.0, 4000.0, trace[len(trace) // 2].arrival_ms):
        part = run(cut)
        assert part.log == [e for e in full.log if e[0] < cut] and part.log
        assert [(t.task_id, s) for t, s in part.edge_starts] == [(t.task_id, s) for t, s in full.edge_starts
                                                                 if s < cut]
        assert len(part.log) < len(full.log)


@needs_workload
def test_reference_eviction_scan_is_the_default_and_full_is_an_option():
    w = Workload.from_file(WORKLOAD_JSON, "HEAVY")
    trace = make_trace(w, drones=3, duration_s=20, seed=1)
    ref, default = (run_policy("DEM", w, trace, options=o) for o in ({"eviction_scan": "reference"}, {}))
    full = run_policy("DEM", w, trace, options={"eviction_scan": "full"})
    assert [t.state for t in ref.tasks] == [t.state for t in default.tasks]
    assert [t.state for t in ref.tasks] != [t.state for t in full.tasks]  # the scans decide differently here


# --------------------------------------------------------------------------------------------- upper bound
def test_upper_bound_on_a_hand_built_case():
    """Two tasks, both [0, 1000]: X edge 600 (benefit 100, edge cost 0, no cloud in time), Y edge 600 (benefit 80,
    cloud cost 50, cloud 300). Only one fits on the edge: the best schedule is X on the edge + Y on the cloud = 130.
    The LP relaxes the choice: X wholly (gain 100) and 400/600 of Y's edge gain (80 - 30 = 50) on top of Y's cloud
    value 30: 100 + 30 + 2/3 x 50 = 163.3 >= 130."""
    w = Workload.from_dict({"models": {
        "X": {"edge_ms": 600, "cloud_ms": 5000, "benefit": 100, "edge_cost": 0, "cloud_cost": 0},
        "Y": {"edge_ms": 600, "cloud_ms": 300, "benefit": 80, "edge_cost": 0, "cloud_cost": 50}},
        "loads": {"T": {"X": 1000, "Y": 1000}}}, "T")
    tasks = [AnalyticsTask(1, "d", "X", 0.0, 1000.0), AnalyticsTask(2, "d", "Y", 0.0, 1000.0)]
    b = utility_upper_bound(tasks, w, lambda t: w[t.model].edge_ms, lambda t, s: w[t.model].cloud_ms)
    assert b["bound"] == pytest.approx(100 + 30 + 50 * 400 / 600) and b["cloud_part"] == pytest.approx(30.0)
    only_x = utility_upper_bound(tasks[:1], w, lambda t: w[t.model].edge_ms, lambda t, s: w[t.model].cloud_ms)
    assert only_x["bound"] == pytest.approx(100.0) and only_x["edge_tasks"] == 1


@needs_workload
@pytest.mark.parametrize("sigma", [0.0, 0.1])
def test_upper_bounds_are_above_every_policy_on_the_same_draws(sigma):
    """The LP and the exact (clairvoyant) bound hold on every seed: no policy's utility exceeds them, and the exact
    optimum never exceeds the LP relaxation."""
    w = Workload.from_file(WORKLOAD_JSON, "HEAVY")
    per_edge = fleet_tasks(fleet_trace(w, 3, 15.0, 2, 3), w)
    (edge, tasks), = per_edge.items()
    ej, cj = Jitter("lognormal", 0.05), Jitter("lognormal", sigma)
    h = Harness(make_analytics_scheduler("CLOUD", w), edge_jitter=ej, cloud_jitter=cj, seed=2, edge_id=edge)
    lp = utility_upper_bound(tasks, w, h.edge_hold_ms, h.cloud_round_trip_ms)["bound"]
    exact = utility_upper_bound(tasks, w, h.edge_hold_ms, h.cloud_round_trip_ms, method="exact")
    assert exact["bound"] <= lp + 1e-6
    for name in ("DEM", "DEMS", "GAINPLAN", "EVPLAN", "LAPLAN", "CLOUD"):
        assert run_fleet(name, w, per_edge, seed=2, edge_jitter=ej, cloud_jitter=cj)["utility"] <= exact["bound"] + 1e-6
    # its schedule is feasible: one task at a time, each within its window at its realised time
    by_id, free = {t.task_id: t for t in tasks}, float("-inf")
    for tid, start in exact["edge_schedule"]:
        t = by_id[tid]
        assert start >= max(free, t.arrival_ms) - 1e-9 and start + h.edge_hold_ms(t) <= t.deadline_ms + 1e-9
        free = start + h.edge_hold_ms(t)


def _brute_force_bound(tasks, w, edge_ms, cloud_ok):
    """max over every edge subset and order (left-shifted, on time) of its edge utility + the others' cloud value"""
    best = 0.0
    fallback = {t.task_id: (w[t.model].cloud_utility if cloud_ok(t) else 0.0) for t in tasks}
    for r in range(len(tasks) + 1):
        for sub in itertools.combinations(tasks, r):
            for perm in itertools.permutations(sub):
                f, ok = float("-inf"), True
                for t in perm:
                    f = max(f, t.arrival_ms) + edge_ms(t)
                    ok = ok and f <= t.deadline_ms
                if ok:
                    best = max(best, sum(max(0.0, fallback[t.task_id]) for t in tasks if t not in sub)
                               + sum(w[t.model].edge_utility for t in sub))
                    break
    return best


def test_exact_bound_equals_brute_force_on_tiny_traces():
    w = Workload.from_dict({"models": {
        "X": {"edge_ms": 300, "cloud_ms": 250, "benefit": 200, "edge_cost": 5, "cloud_cost": 150},
        "Y": {"edge_ms": 150, "cloud_ms": 5000, "benefit": 60, "edge_cost": 1, "cloud_cost": 0},
        "Z": {"edge_ms": 100, "cloud_ms": 300, "benefit": 50, "edge_cost": 1, "cloud_cost": 10}},
        "loads": {"T": {"X": 400, "Y": 500, "Z": 350}}}, "T")
    rng = random.Random(5)
    for k in range(40):
        tasks = []
        for i in range(rng.randint(1, 6)):
            m, at = rng.choice("XYZ"), rng.choice([0.0, 50.0, 120.0, rng.uniform(0, 400)])
            tasks.append(AnalyticsTask(i, "d", m, at, at + w[m].deadline_ms))
        jit = {t.task_id: rng.uniform(0.8, 1.2) for t in tasks}
        edge_ms = lambda t: w[t.model].edge_ms * jit[t.task_id]  # noqa: E731
        cloud_ms = lambda t, s: w[t.model].cloud_ms * (2 - jit[t.task_id])  # noqa: E731
        b = utility_upper_bound(tasks, w, edge_ms, cloud_ms, method="exact")["bound"]
        assert b == pytest.approx(_brute_force_bound(tasks, w, edge_ms,
                                                     lambda t: t.arrival_ms + cloud_ms(t, 0) <= t.deadline_ms))


def test_non_anticipative_bound_values_each_task_by_its_expected_reward():
    """One edge-only task, profile 100 ms, window exactly 100 ms, lognormal edge jitter 0.05: started at its
    arrival it is on time with P(X <= 1) = Phi(sigma / 2) ~ 0.510. The bound credits the next level above (0.55 x
    benefit - edge cost): >= the true expectation, within one level. A cloud-only task is worth P * benefit -
    cost with P its on-time chance at arrival; with no jitter both bounds are the clairvoyant one."""
    w = Workload.from_dict({"models": {
        "E": {"edge_ms": 100, "cloud_ms": 9000, "benefit": 100, "edge_cost": 1, "cloud_cost": 0},
        "C": {"edge_ms": 900, "cloud_ms": 500, "benefit": 100, "edge_cost": 1, "cloud_cost": 50}},
        "loads": {"T": {"E": 100, "C": 550}}}, "T")
    e, c = AnalyticsTask(1, "d", "E", 0.0, 100.0), AnalyticsTask(2, "d", "C", 0.0, 550.0)
    p_edge = lognormal_on_time_chance(100.0, 0.05, 100.0)
    p_cloud = lognormal_on_time_chance(500.0, 0.1, 550.0)
    assert p_edge == pytest.approx(0.510, abs=1e-3) and 0.8 < p_cloud < 0.9
    b = utility_upper_bound([e, c], w, lambda t: 100.0, lambda t, s: 0.0, method="exact",
                            cloud_chance=lambda t, s: lognormal_on_time_chance(w[t.model].cloud_ms, 0.1,
                                                                               t.deadline_ms - s),
                            edge_slack=lambda t, p: lognormal_slack(w[t.model].edge_ms, 0.05, p))
    assert b["cloud_part"] == pytest.approx(p_cloud * 100 - 50)
    assert p_edge * 100 - 1 <= b["edge_gain"] <= (p_edge + 0.05) * 100 - 1
    exact = utility_upper_bound([e, c], w, lambda t: w[t.model].edge_ms, lambda t, s: w[t.model].cloud_ms,
                                method="exact")
    flat = utility_upper_bound([e, c], w, lambda t: w[t.model].edge_ms, lambda t, s: w[t.model].cloud_ms,
                               method="exact", cloud_chance=lambda t, s: lognormal_on_time_chance(w[t.model].cloud_ms, 0,
                                                                                         t.deadline_ms - s),
                               edge_slack=lambda t, p: lognormal_slack(w[t.model].edge_ms, 0.0, p))
    assert exact["bound"] == pytest.approx(flat["bound"]) == pytest.approx(99 + 50)


def test_lognormal_on_time_chance_matches_the_harness_draws():
    from aerodaas.schedulers.dispatch.emulation import seeded_rng

    j = Jitter("lognormal", 0.1)
    draws = [600.0 * j.factor(seeded_rng(1, "cloud", "e", i)) for i in range(4000)]
    for slack in (560.0, 600.0, 680.0):
        assert lognormal_on_time_chance(600.0, 0.1, slack) == pytest.approx(
            sum(d <= slack for d in draws) / len(draws), abs=0.02)
    assert lognormal_slack(600.0, 0.1, lognormal_on_time_chance(600.0, 0.1, 640.0)) == pytest.approx(640.0)


# --------------------------------------------------------------------------------------------- runtime summary
def _run_row(seed: int, utility: float, p99: float, valid: bool) -> dict:
    timing = {k: {"n": 10, "p99": p99} for k in ("arrival_lateness", "edge_hold_error", "cloud_rtt_error",
                                                 "poll_lateness", "cloud_reply_margin")}
    return {"scheduler": "DEM", "load": "HEAVY", "cloud_sigma": 0.1, "scenario": "none", "drones_per_edge": 3,
            "drones": 6, "edges": 2, "seed": seed, "utility": utility, "on_time_rate": 0.5, "cloud_cost": 1.0,
            "edge_cost": 1.0, "states": {"done_on_time": 5, "expired_edge": 1}, "counters": {"steals": 2},
            "timing_ms": timing, "emulation_p99_ms": p99, "emulation_valid": valid}


def test_runtime_summary_marks_a_configuration_invalid_if_any_seed_ran_over_the_emulation_bound():
    ok = summarize_runs([_run_row(0, 10.0, 2.0, True), _run_row(1, 14.0, 3.0, True)])
    (row,) = ok
    assert row["utility"]["per_seed"] == [10.0, 14.0] and row["utility"]["mean"] == 12.0
    assert row["emulation_valid"] and row["seeds"] == [0, 1] and row["counters"]["steals"]["mean"] == 2
    (bad,) = summarize_runs([_run_row(0, 10.0, 2.0, True), _run_row(1, 14.0, 80.0, False)])
    assert not bad["emulation_valid"] and bad["emulation_p99_ms"] == [2.0, 80.0]


# --------------------------------------------------------------------------------------------- CLI
@needs_workload
def test_cli_harness_mode_prints_the_sweep_json_and_refuses_bad_input(tmp_path, monkeypatch, capsys):
    from aerodaas.cli import main

    monkeypatch.setenv("AERODAAS_DATA_DIR", str(DATA_DIR))
    png = tmp_path / "h.png"
    rc = main(["bench", "schedulers", "--harness", "--seeds", "2", "--load", "MEDIUM", "--cloud-sigma", "0.1",
               "--drones-per-edge", "2", "--scenarios", "none", "--duration", "5", "--drones", "2", "--schedulers",
               "DEM", "EVPLAN", "--processes", "1", "--estimator", "p95:10", "--json", "--plot", str(png)])
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    assert [r["scheduler"] for r in res["results"]] == ["DEM", "EVPLAN"]
    assert res["config"]["options"] == {"estimator": "p95:10"}
    assert all(len(r["utility"]["per_seed"]) == 2 for r in res["results"])
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert main(["bench", "schedulers", "--harness", "--estimator", "median", "--duration", "1", "--seeds", "1",
                 "--plot", str(png)]) == 2
    with pytest.raises(SystemExit):
        main(["bench", "schedulers", "--harness", "--cloud-sigma", "-1"])


@needs_workload
def test_cli_option_reaches_the_scheduler_that_has_it_and_refuses_what_none_has(tmp_path, monkeypatch, capsys):
    """``--option KEY=JSON`` sets a scheduler option for the schedulers that have it (here LAPLAN's lookahead: with
    ``horizon_ms=0`` it predicts nothing), is recorded in the JSON, and is refused when no scheduler of the run has
    it or its value is out of range (e.g. ``replan_tolerance_ms``, to rerun tables made before its default changed)."""
    from aerodaas.cli import main

    monkeypatch.setenv("AERODAAS_DATA_DIR", str(DATA_DIR))
    common = ["bench", "schedulers", "--harness", "--seeds", "1", "--load", "HEAVY", "--cloud-sigma", "0.1",
              "--drones-per-edge", "3", "--scenarios", "none", "--duration", "20", "--drones", "3", "--processes",
              "1", "--no-bound", "--json", "--plot", str(tmp_path / "h.png")]
    predicted = {}
    for opt in ([], ["--option", "horizon_ms=0", "--option", "replan_tolerance_ms=0"]):
        assert main([*common, "--schedulers", "DEM", "LAPLAN", *opt]) == 0
        res = json.loads(capsys.readouterr().out)
        assert res["config"]["options"] == ({"horizon_ms": 0, "replan_tolerance_ms": 0} if opt else {})
        laplan = next(r for r in res["results"] if r["scheduler"] == "LAPLAN")
        predicted[bool(opt)] = laplan["counters"].get("arrived_as_predicted", {"mean": 0})["mean"]
    assert predicted[False] > 0 and predicted[True] == 0
    assert main([*common, "--schedulers", "DEM", "--option", "replan_tolerance_ms=0"]) == 2
    assert "no scheduler of this run has it" in capsys.readouterr().err
    assert main([*common, "--schedulers", "LAPLAN", "--option", "replan_tolerance_ms=500"]) == 2
    assert "replan_tolerance_ms" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([*common, "--option", "replan_tolerance_ms"])


@pytest.mark.parametrize("argv, named", [
    (["--harness", "--network-variability", "const:500"], "--network-variability"),
    (["--harness", "--cloud-jitter", "lognormal:0.3"], "--cloud-jitter"),
    (["--harness", "--repeat", "2", "--cloud-nodes", "2"], "--cloud-nodes, --repeat"),
    (["--processes", "1"], "--processes"),
    (["--no-bound", "--exact-bound", "HEAVY"], "--no-bound, --exact-bound"),
    (["--exact-bound-budget-s", "5"], "--exact-bound-budget-s"),
])
def test_an_option_the_mode_does_not_use_is_refused_naming_it(argv, named, tmp_path, capsys):
    """The harness ignored --network-variability and --cloud-jitter (with const:500 the utility was
    40,786 either way); an option the chosen mode would not use is exit 2, before any run (no Ray, no job)."""
    from aerodaas.cli import main

    assert main(["bench", "schedulers", *argv, "--plot", str(tmp_path / "h.png")]) == 2
    err = capsys.readouterr().err
    assert f"aerodaas bench schedulers: {named}: not used by" in err, err
    assert not (tmp_path / "h.png").exists()


# --------------------------------------------------------------------------------------------- bounded work
def _spin():
    while True:
        pass


def _grab():
    return [bytearray(2 ** 20) for _ in range(400)]  # 400 MiB


def test_bounded_runs_within_its_budget_or_says_what_ran_out():
    """The exact bound ran over 5 min and 2 GB on a stall-and-flush trace; now it is cut off and said."""
    from aerodaas.bench.bound import Budget, bounded

    assert bounded(lambda: 6 * 7, Budget(60.0, 256.0)) == ("ok", 42)
    assert bounded(_spin, Budget(0.5, 256.0)) == ("time", None)
    assert bounded(_grab, Budget(60.0, 64.0)) == ("memory", None)
    with pytest.raises(RuntimeError, match="ZeroDivisionError"):
        bounded(lambda: 1 / 0, Budget(60.0, 256.0))
    with pytest.raises(ValueError, match="budget"):
        Budget(0.0, 1.0)


@needs_workload
def test_an_exact_bound_out_of_budget_is_not_computed_with_the_lp_beside_it():
    from aerodaas.bench.bound import Budget

    res = run_sweep(loads=["HEAVY"], sigmas=[0.0], drones_per_edge=[2], scenarios=["none"], seeds=[0, 1], edges=1,
                    duration_s=8, schedulers=["DEM"], processes=1, workload_path=WORKLOAD_JSON,
                    bound_budget=Budget(1e-3, 256.0))
    r = res["results"][0]
    assert r["upper_bound_kind"] == "lp" and "bound_na" not in r and r["bound_lp"]["mean"] > 0
    assert r["bounds_not_computed"]["seed 0"]["exact"].startswith("time budget ran out on edge00")
    assert res["config"]["exact_bound_budget"] == {"time_s": 1e-3, "memory_mb": 256.0}
