"""TwoOptScheduler, fixed ORDERED runs in the base scheduler, the exact/lower-bound references and
``aerodaas bench tours`` (no timing assertions: timings are measured by the benchmark, not here)."""
import itertools
import json
import math
import pickle

import numpy as np
import pytest

from aerodaas.bench.tours import disaster_survey, held_karp_open_path, open_path_lower_bound, random_instance
from aerodaas.cli import main
from aerodaas.model.types import (AeroNavigation, NavigationType, PriorityQueue, SchedulingType, VelocityCommand,
                                  Waypoint)
from aerodaas.schedulers import NearestNeighborScheduler, TrajectoryScheduler, TwoOptScheduler
from aerodaas.schedulers.two_opt import improve_path, nearest_neighbour_path, node_cost_matrix, path_cost

START = (0.0, 0.0, 0.0)
length = TrajectoryScheduler.tour_length


def wp(name, x, y, z=10.0):
    return Waypoint(id=name, x=x, y=y, z=z)


def instance(seed, n):
    return random_instance(np.random.default_rng([seed, n]), n)


def matrix(wps, start=START):
    pts = [(w.x, w.y, w.z) for w in wps]
    return node_cost_matrix(pts, pts, start)


def optimum(wps, start=START):
    return held_karp_open_path(matrix(wps, start))[0]


def brute_force(D):
    m = D.shape[0] - 1
    return min(path_cost(D, (0,) + p) for p in itertools.permutations(range(1, m + 1)))


def ids(items):
    return [i.id for i in items]


# ------------------------------------------------------------------------------------------ references
@pytest.mark.parametrize("m", [1, 2, 3, 5, 7])
def test_held_karp_is_exact_also_for_asymmetric_runs(m):
    rng = np.random.default_rng(m)
    entries = rng.uniform(-50, 50, (m, 3))
    exits = entries + rng.uniform(-20, 20, (m, 3))  # runs: entered at one point, left at another
    for D in (node_cost_matrix(entries, entries, START), node_cost_matrix(entries, exits, (3.0, -4.0, 1.0))):
        cost, path = held_karp_open_path(D)
        assert sorted(path) == list(range(m + 1)) and path[0] == 0
        assert cost == pytest.approx(path_cost(D, path), abs=1e-9)
        assert cost == pytest.approx(brute_force(D), abs=1e-9)


def test_lower_bound_never_exceeds_the_optimum_and_is_tight():
    ratios = []
    for n in (2, 4, 6, 8, 10, 11):
        for seed in range(4):
            D = matrix(instance(seed, n))
            opt = held_karp_open_path(D)[0]
            # any upper estimate steers the step size; the bound stays valid even with a poor one
            for upper in (opt, 1.3 * opt):
                lb = open_path_lower_bound(D, upper=upper)
                assert lb <= opt + 1e-6
                ratios.append(lb / opt)
    assert min(ratios) > 0.9 and float(np.median(ratios)) > 0.99


# ------------------------------------------------------------------------------------------ the scheduler
@pytest.mark.parametrize("n", [15, 40, 120])
def test_two_opt_is_never_longer_than_nearest_neighbour(n):
    nn, two = NearestNeighborScheduler(), TwoOptScheduler()
    for seed in range(3):
        wps = instance(seed, n)
        a, b = nn.order(list(wps), START), two.order(list(wps), START)
        assert sorted(ids(b)) == sorted(ids(wps)) and all(any(x is w for w in wps) for x in b)
        assert length(b, START) <= length(a, START) + 1e-9
    # and clearly shorter on average at this size
    assert length(two.order(instance(7, n), START), START) < length(nn.order(instance(7, n), START), START)


@pytest.mark.parametrize("n", [1, 2, 3, 5, 7, 9])
def test_two_opt_finds_the_held_karp_optimum_on_small_instances(n):
    for seed in range(5):
        wps = instance(seed, n)
        opt = optimum(wps)
        exact = TwoOptScheduler()  # n <= exact_max: Held-Karp itself
        heuristic = TwoOptScheduler(exact_max=0)  # NN + 2-opt + Or-opt + kicks only
        assert length(exact.order(list(wps), START), START) == pytest.approx(opt, abs=1e-6)
        assert length(heuristic.order(list(wps), START), START) == pytest.approx(opt, abs=1e-6)


def test_two_opt_heuristic_is_near_optimal_above_the_exact_limit():
    for seed in range(3):
        wps = instance(seed, 12)
        tour = TwoOptScheduler(exact_max=0).order(list(wps), START)
        assert length(tour, START) <= 1.02 * optimum(wps)


def test_two_opt_is_deterministic_and_validates_its_options():
    wps = instance(3, 60)
    assert ids(TwoOptScheduler().order(list(wps), START)) == ids(TwoOptScheduler().order(list(wps), START))
    assert TwoOptScheduler().order([], START) == []
    for bad in ({"or_opt_max": 4}, {"neighbours": 0}, {"exact_max": 13}, {"kicks": -1}):
        with pytest.raises(ValueError):
            TwoOptScheduler(**bad)
    with pytest.raises(ValueError):
        improve_path(matrix(wps[:3]), [1, 0, 2, 3])


def test_local_search_handles_asymmetric_runs():
    """Nodes with distinct entry/exit points (fixed runs): never worse than NN, never reverses a run."""
    rng = np.random.default_rng(5)
    for m in (6, 8, 10):
        entries = rng.uniform(-100, 100, (m, 3))
        exits = entries + rng.uniform(-40, 40, (m, 3))
        D = node_cost_matrix(entries, exits, START)
        nn = nearest_neighbour_path(D)
        p = improve_path(D, nn, kicks=150)
        assert sorted(p) == list(range(m + 1)) and path_cost(D, p) <= path_cost(D, nn) + 1e-9
        assert path_cost(D, p) <= 1.05 * held_karp_open_path(D)[0]


# ------------------------------------------------------------------------------------------ fixed ORDERED runs
def _mission_with_a_run(sched):
    """An ORDERED survey leg along y = 0 (a fixed run), then UNORDERED points interleaved with it."""
    run = [wp(f"r{i}", x, 0.0) for i, x in enumerate((0.0, 40.0, 80.0, 120.0))]
    free = [wp("f1", 20.0, 5.0), wp("f2", 60.0, -5.0), wp("f3", 100.0, 5.0), wp("f4", 130.0, 30.0)]
    sched.generate_navigation(AeroNavigation(NavigationType.DISTANCE_DRIVEN, run, SchedulingType.ORDERED))
    sched.add_navigation(AeroNavigation(NavigationType.ANALYTICS_DRIVEN, free, SchedulingType.UNORDERED),
                         priority=2, position=(-10.0, 0.0, 10.0))
    return run, free


def _assert_run_contiguous(items, run_ids):
    got = ids(items)
    k = got.index(run_ids[0])
    assert got[k:k + len(run_ids)] == run_ids, got


@pytest.mark.parametrize("cls", [TwoOptScheduler, NearestNeighborScheduler, TrajectoryScheduler])
def test_ordered_runs_stay_contiguous_and_in_order(cls):
    s = cls()
    run, free = _mission_with_a_run(s)
    (m,) = s.queue.entries
    assert sorted(ids(m.items)) == sorted(ids(run + free))
    _assert_run_contiguous(m.items, ids(run))
    tags = dict(zip(ids(m.items), m.segment_ids))
    assert len({tags[r.id] for r in run}) == 1 and tags["r0"] > 0 and all(tags[f.id] == 0 for f in free)
    if cls is TrajectoryScheduler:
        assert ids(m.items) == ids(run + free)  # the base class keeps the given order


def test_two_opt_plans_runs_optimally_with_entry_and_exit():
    s = TwoOptScheduler()
    run, free = _mission_with_a_run(s)
    got = s.queue.entries[0].items
    nodes = [run] + [[f] for f in free]
    entries = [(n[0].x, n[0].y, n[0].z) for n in nodes]
    exits = [(n[-1].x, n[-1].y, n[-1].z) for n in nodes]
    inner = length(run[1:], (run[0].x, run[0].y, run[0].z))
    opt = held_karp_open_path(node_cost_matrix(entries, exits, (-10.0, 0.0, 10.0)))[0] + inner
    assert length(got, (-10.0, 0.0, 10.0)) == pytest.approx(opt, abs=1e-6)
    # without the run constraint the free points would be interleaved with the survey leg
    free_plan = TwoOptScheduler().order(run + free, (-10.0, 0.0, 10.0))
    with pytest.raises(AssertionError):
        _assert_run_contiguous(free_plan, ids(run))


def test_run_bookkeeping_insertions_pops_and_pickling():
    s = TwoOptScheduler()
    run, free = _mission_with_a_run(s)
    m = s.queue.entries[0]
    # an ORDERED insertion strictly inside the run joins it; an appended ORDERED navigation is a run of its own
    k = ids(m.items).index("r1")
    s.add_navigation([wp("j", 60.0, 1.0)], index=k + 1, priority=2)
    s.add_navigation(AeroNavigation(waypoints=[wp("t1", 0.0, 90.0), wp("t2", 5.0, 90.0)]), priority=2)
    tags = dict(zip(ids(m.items), m.segment_ids))
    assert tags["j"] == tags["r0"] and tags["t1"] == tags["t2"] not in (0, tags["r0"])
    # items popped directly (as an actor may do) cannot misalign the tags
    head = m.items[0]
    m.items.pop(0)
    s.add_navigation(AeroNavigation(waypoints=[VelocityCommand(vx=1.0)]), priority=2)  # ORDERED: no re-plan
    s.add_navigation(AeroNavigation(NavigationType.ANALYTICS_DRIVEN, [wp("g", 50.0, 50.0)], SchedulingType.UNORDERED),
                     priority=2, position=(head.x, head.y, head.z))
    assert isinstance(m.items[-1], VelocityCommand)  # velocity commands stay after the waypoints
    run_now = [i for i in ["r0", "r1", "j", "r2", "r3"] if i in ids(m.items)]
    _assert_run_contiguous(m.items, run_now)
    _assert_run_contiguous(m.items, ["t1", "t2"])
    # the scheduler travels to its Ray actor by pickling: the runs survive it
    s2 = pickle.loads(pickle.dumps(s))
    m2 = s2.queue.entries[0]
    assert ids(m2.items) == ids(m.items) and m2.segment_ids == m.segment_ids
    s2.add_navigation(AeroNavigation(NavigationType.ANALYTICS_DRIVEN, [wp("h", -50.0, 20.0)], SchedulingType.UNORDERED),
                      priority=2, position=(0.0, 0.0, 10.0))
    _assert_run_contiguous(m2.items, run_now)
    _assert_run_contiguous(m2.items, ["t1", "t2"])


def test_base_fallback_rejects_a_plugin_that_loses_waypoints():
    class Broken(TrajectoryScheduler):
        def order(self, waypoints, start):
            return list(waypoints)[:-1]

    s = Broken()
    with pytest.raises(ValueError, match="must return the waypoints"):
        _mission_with_a_run(s)


def test_remove_queued_takes_items_by_predicate_and_priority_in_one_step():
    s = TrajectoryScheduler()
    s.generate_navigation(PriorityQueue([wp("a1", 1.0, 0.0), wp("b1", 2.0, 0.0), wp("a2", 3.0, 0.0)], 2))
    s.generate_navigation(PriorityQueue([wp("a9", 9.0, 0.0)], 1))
    s.generate_navigation(PriorityQueue([wp("a5", 5.0, 0.0)], 3))
    cleared = s.cleared
    gone = s.remove_queued(lambda i: i.id.startswith("a"), priority=2)
    assert ids(gone) == ["a1", "a2"] and s.cleared == cleared + 1
    assert {m.priority: ids(m.items) for m in s.missions()} == {1: ["a9"], 2: ["b1"], 3: ["a5"]}
    assert ids(s.remove_queued(lambda i: i.id in ("a9", "a5"))) == ["a9", "a5"]
    assert [m.priority for m in s.missions()] == [2]  # the missions left empty are gone
    assert s.remove_queued(lambda i: False) == [] and s.cleared == cleared + 3  # every call counts

    def boom(item):
        raise RuntimeError("predicate failed")

    with pytest.raises(RuntimeError, match="predicate failed"):
        s.remove_queued(boom)
    assert ids(s.queued()) == ["b1"]  # a failing predicate changes nothing


def test_revise_items_replaces_waypoints_and_keeps_them_in_their_fixed_run():
    s = TwoOptScheduler()
    run, free = _mission_with_a_run(s)
    clamped = wp("r1", 40.0, 0.0, 8.0)  # what the pre-flight safety check puts in place of the original r1

    def revise(m):
        return [clamped if i.id == "r1" else i for i in m.items]

    s.revise_items(revise)
    (m,) = s.missions()
    assert any(i is clamped for i in m.items) and not any(i is run[1] for i in m.items)
    s.add_navigation(AeroNavigation(NavigationType.ANALYTICS_DRIVEN, [wp("g", 50.0, 40.0)], SchedulingType.UNORDERED),
                     priority=2, position=(-10.0, 0.0, 10.0))
    _assert_run_contiguous(s.missions()[0].items, ids(run))  # the revised waypoint is still part of its run
    before = ids(s.queued())
    with pytest.raises(ValueError, match="unsafe"):
        s.revise_items(lambda m: (_ for _ in ()).throw(ValueError("unsafe")))
    assert ids(s.queued()) == before  # all or nothing


# ------------------------------------------------------------------------------------------ through INavigate
def test_priorities_are_never_mixed():
    s = TwoOptScheduler()
    hi = [wp(f"h{i}", 10.0 * i, 3.0) for i in range(5)]
    lo = [wp(f"l{i}", 10.0 * i + 5.0, 0.0) for i in range(5)]
    s.generate_navigation(PriorityQueue(AeroNavigation(NavigationType.DISTANCE_DRIVEN, lo, SchedulingType.UNORDERED), 2))
    s.add_navigation(PriorityQueue(AeroNavigation(NavigationType.ANALYTICS_DRIVEN, hi, SchedulingType.UNORDERED), 1),
                     position=(0.0, 0.0, 10.0))
    s.add_navigation(AeroNavigation(NavigationType.ANALYTICS_DRIVEN, [wp("l9", 2.0, 1.0)], SchedulingType.UNORDERED),
                     priority=2, position=(0.0, 0.0, 10.0))
    by_prio = {m.priority: set(ids(m.items)) for m in s.queue.entries}
    assert by_prio == {1: {w.id for w in hi}, 2: {w.id for w in lo} | {"l9"}}
    assert s.current(0.0)[0].priority == 1


def test_end_to_end_generate_then_replan_from_the_drone_position():
    s = TwoOptScheduler()
    wps = instance(11, 9)
    nav = s.generate_navigation(AeroNavigation(NavigationType.DISTANCE_DRIVEN, wps, SchedulingType.UNORDERED))
    assert nav.scheduling_type == SchedulingType.ORDERED
    assert length(nav.waypoints, s.start) == pytest.approx(optimum(wps, s.start), abs=1e-6)
    # fly to the first two waypoints, then analytics inject three more (UNORDERED, same priority)
    pos = None
    for _ in range(2):
        _, w = s.current(0.0)
        pos = (w.x, w.y, w.z)
        assert s.complete(w.id)
    extra = [wp("x1", 400.0, -400.0, 30.0), wp("x2", -450.0, 450.0, 20.0), wp("x3", 10.0, 10.0, 15.0)]
    s.add_navigation(AeroNavigation(NavigationType.ANALYTICS_DRIVEN, extra, SchedulingType.UNORDERED),
                     priority=2, position=pos)
    left = s.queue.entries[0].items
    assert len(left) == 10 and {"x1", "x2", "x3"} <= set(ids(left))
    assert length(left, pos) == pytest.approx(optimum(left, pos), abs=1e-6)  # re-planned from ``pos``
    nn = NearestNeighborScheduler().order(list(left), pos)
    assert length(left, pos) <= length(nn, pos) + 1e-9


def test_disaster_survey_saves_distance():
    ds = disaster_survey()
    assert ds["altitude_m"] == 2.0 and len(ds["survey"]) == 4 and len(ds["injected"]) == 3
    for sc in ds["scenarios"]:
        two, nn = sc["schedulers"]["two_opt"], sc["schedulers"]["nearest_neighbor"]
        assert two["distance_m"] == pytest.approx(sc["optimal_replan_m"], abs=1e-3)
        assert two["distance_m"] <= nn["distance_m"] + 1e-9 and two["saved_m"] > 0
        assert two["order"][0] == "s1" and sorted(two["order"]) == sorted(ds["given_order"])
    ordered = next(sc for sc in ds["scenarios"] if sc["survey_scheduling"] == "ORDERED")
    for v in ordered["schedulers"].values():
        _assert_run_contiguous([Waypoint(id=i, x=0, y=0, z=0) for i in v["order"]], ["s2", "s3", "s4"])


# ------------------------------------------------------------------------------------------ CLI
def test_cli_bench_tours_json(capsys, tmp_path):
    out = tmp_path / "tours.json"
    rc = main(["bench", "tours", "--json", "--sizes", "10,20", "--instances", "2", "--repeats", "1",
               "--seed", "3", "--out", str(out)])
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    assert json.loads(out.read_text()) == res
    assert res["benchmark"] == "tours"
    assert {"cpu_count", "python", "platform"} <= set(res["machine"])
    assert {(r["size"], r["scheduler"]) for r in res["results"]} == {
        (n, s) for n in (10, 20) for s in ("nearest_neighbor", "two_opt")}
    for r in res["results"]:
        assert r["instances"] == 2
        assert r["reference"] == ("exact" if r["size"] <= 12 else "lower_bound")
        assert set(r["ratio_to_reference"]) == {"median", "max"} and set(r["plan_ms"]) == {"median", "max"}
        assert 1.0 - 1e-9 <= r["ratio_to_reference"]["median"] <= r["ratio_to_reference"]["max"]
        assert math.isfinite(r["plan_ms"]["max"])
    two10 = next(r for r in res["results"] if r["size"] == 10 and r["scheduler"] == "two_opt")
    assert two10["ratio_to_reference"]["max"] == pytest.approx(1.0, abs=1e-4)
    assert {"scenarios", "altitude_m", "survey", "injected"} <= set(res["disaster_survey"])


def test_cli_bench_tours_table_and_bad_arguments(capsys):
    assert main(["bench", "tours", "--sizes", "6", "--instances", "1", "--repeats", "1"]) == 0
    text = capsys.readouterr().out
    assert "two_opt" in text and "nearest_neighbor" in text and "disaster survey" in text
    with pytest.raises(SystemExit):
        main(["bench", "tours", "--sizes", "ten"])
    with pytest.raises(SystemExit):
        main(["bench"])
