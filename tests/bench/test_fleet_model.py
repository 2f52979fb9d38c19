"""The fleet cost model (``aerodaas/bench/fleet_model.py``) on synthetic ``bench fleet --edge-nodes N`` reports:
reports are generated from known costs, and the fit must find those costs again and the projection follow its
formulas. Pure: no Ray, no clock."""
from __future__ import annotations

import json
import math

import pytest

from aerodaas import cli
from aerodaas.bench import fleet_model
from aerodaas.bench.fleet_model import fit, project

#: the costs the synthetic reports are made of
COST = {"drone_cpu": 0.07, "rec_cpu": 0.01, "raylet": 0.02, "other": 0.03, "gcs": 0.015, "driver": 0.04,
        "actor_pss": 85.0, "raylet_pss": 60.0, "other_pss": 150.0, "rec_pss": 110.0, "gcs_pss": 40.0,
        "driver_pss": 160.0, "msgs": 75.0, "mb": 0.6}


def _node(j: int, drones: int) -> dict:
    c = COST
    cpu = {"drone_actors": c["drone_cpu"] * drones, "recorder_actors": c["rec_cpu"] * drones,
           "raylet": c["raylet"], "ray_other": c["other"], **({"gcs": c["gcs"], "driver": c["driver"]} if j == 0
                                                               else {})}
    pss = {"drone_actors": c["actor_pss"] * drones, "raylet": c["raylet_pss"], "ray_other": c["other_pss"],
           "recorder_actors": c["rec_pss"], **({"gcs": c["gcs_pss"], "driver": c["driver_pss"]} if j == 0 else {})}
    return {"node": j, "head": j == 0, "drones": drones, "drone_actors": [f"aerodaas/r/drone/d{j}{i}"
                                                                          for i in range(drones)],
            "cpu_s_per_sim_s": cpu, "pss_mb": pss, "pss_mb_per_drone_actor": c["actor_pss"],
            "recorder": {"messages_per_s": c["msgs"] * drones, "mb_per_s": c["mb"] * drones}}


def _report(per_node: list[int]) -> dict:
    nodes = [_node(j, d) for j, d in enumerate(per_node)]
    drones = sum(per_node)
    # GCS: a drone actor per drone, a recorder per node and the run's recorder
    classes = {"DroneActor": drones, "RecorderActor": len(per_node) + 1}
    return {"benchmark": "fleet", "machine": {"cpu_count": 2, "memory_gib": 8.0},
            "results": [{"drones": drones, "drones_per_actor": 1, "nodes": nodes,
                         "gcs_actors": sum(classes.values()), "gcs_actor_classes": classes}]}


def test_the_fit_finds_the_costs_the_runs_were_made_of():
    m = fit([_report([2]), _report([4]), _report([2, 2]), _report([4, 4])])
    c = COST
    assert m.cpu_per_drone == pytest.approx(c["drone_cpu"] + c["rec_cpu"])
    assert m.cpu_node_fixed == pytest.approx(c["raylet"] + c["other"])
    assert m.cpu_head_extra == pytest.approx(c["gcs"] + c["driver"])
    assert m.pss_per_drone_actor == pytest.approx(c["actor_pss"])
    assert m.pss_node_fixed == pytest.approx(c["raylet_pss"] + c["other_pss"] + c["rec_pss"])
    assert m.pss_head_extra == pytest.approx(c["gcs_pss"] + c["driver_pss"])
    assert m.recorder_msgs_per_drone == pytest.approx(c["msgs"])
    assert m.recorder_mb_per_drone == pytest.approx(c["mb"])
    assert m.gcs_actors_per_node == pytest.approx(1.0) and m.gcs_actors_per_run == pytest.approx(1.0)
    assert (m.points, m.runs) == (6, 4)


def test_the_projection_follows_its_formulas_and_names_what_breaks_first():
    m = fit([_report([2]), _report([3, 3])])
    c = COST
    cpu_cap = math.floor((4.0 - c["raylet"] - c["other"]) / (c["drone_cpu"] + c["rec_cpu"]))  # 49
    mem_cap = math.floor((1024 * 16.0 - c["raylet_pss"] - c["other_pss"] - c["rec_pss"]) / c["actor_pss"])  # 188
    rec_cap = math.floor(min(8000.0 / c["msgs"], 15.0 / c["mb"]))  # 25 (bytes)
    p = project(m, drones=1000, node_cores=4.0, node_mem_gib=16.0)
    caps = {lim.resource: (lim.drones_per_node, lim.nodes) for lim in p.limits}
    assert caps["CPU"] == (cpu_cap, math.ceil(1000 / cpu_cap))
    assert caps["memory"] == (mem_cap, math.ceil(1000 / mem_cap))
    assert caps["recorder (one per node)"] == (rec_cap, math.ceil(1000 / rec_cap))
    assert p.breaks_first == "recorder (one per node)" and p.edge_nodes == math.ceil(1000 / rec_cap)
    assert p.gcs_actors == 1000 + p.edge_nodes + 1 and p.single_recorder_drones == rec_cap
    assert p.head_cpu == pytest.approx(c["raylet"] + c["other"] + c["gcs"] + c["driver"])

    # a faster recorder: CPU binds; a small node: memory binds
    assert project(m, 1000, 4.0, 16.0, recorder_mb_per_s=1000.0, recorder_msgs_per_s=1e6).breaks_first == "CPU"
    small = project(m, 1000, 64.0, 1.0, recorder_mb_per_s=1000.0, recorder_msgs_per_s=1e6)
    assert small.breaks_first == "memory"
    assert small.limits[0].drones_per_node == math.floor((1024 - c["raylet_pss"] - c["other_pss"] - c["rec_pss"])
                                                         / c["actor_pss"])


def test_packed_actors_divide_the_memory_per_drone():
    rep = _report([4, 4])
    rep["results"][0]["drones_per_actor"] = 4
    m = fit([rep])
    p = project(m, 1000, 64.0, 4.0, recorder_mb_per_s=1000.0, recorder_msgs_per_s=1e6)
    budget = 4096 - COST["raylet_pss"] - COST["other_pss"] - COST["rec_pss"]
    assert {lim.resource: lim.drones_per_node for lim in p.limits}["memory"] == math.floor(budget / (85.0 / 4))


def test_a_row_whose_window_was_cut_short_is_not_fitted():
    cut = _report([9, 9])
    cut["results"][0]["window"] = {"complete": False, "seconds": 0.5, "error": None}
    for p in cut["results"][0]["nodes"]:
        p["cpu_s_per_sim_s"]["drone_actors"] = 0.0  # what a window that closed at once would read
    assert fit([_report([2]), cut]) == fit([_report([2])])


def test_bad_inputs_are_refused_with_the_reason():
    with pytest.raises(ValueError, match="no row with 'nodes'"):
        fit([{"results": [{"drones": 4, "drones_per_actor": 1}]}])
    a, b = _report([2]), _report([2])
    b["results"][0]["drones_per_actor"] = 2
    with pytest.raises(ValueError, match=r"mix drones per actor \[1, 2\]"):
        fit([a, b])
    with pytest.raises(ValueError, match="drones must be >= 1"):
        project(fit([a]), drones=0)
    with pytest.raises(ValueError, match="cannot carry one drone by CPU"):
        project(fit([a]), drones=10, node_cores=0.01)


def test_the_command_prints_the_projection_and_refuses_a_bad_file(tmp_path, capsys):
    run = tmp_path / "run.json"
    run.write_text(json.dumps(_report([2, 2])))
    assert cli.main(["bench", "fleet-model", str(run), "--drones", "1000", "--node-cores", "4",
                     "--node-mem-gib", "16", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    want = project(fit([_report([2, 2])]), 1000, 4.0, 16.0)
    assert out["projection"]["edge_nodes"] == want.edge_nodes and out["projection"]["breaks_first"] == want.breaks_first
    assert cli.main(["bench", "fleet-model", str(run)]) == 0  # the measured machine's 2 cores and 8 GiB
    text = capsys.readouterr().out
    nodes = project(fit([_report([2, 2])]), 1000, 2.0, 8.0).edge_nodes
    assert "breaks first: " in text and f"{nodes:,} + 1 head" in text
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    assert cli.main(["bench", "fleet-model", str(bad)]) == 2
    assert repr(str(bad)) in capsys.readouterr().err
    assert cli.main(["bench", "fleet-model", str(run), "--drones", "0"]) == 2
    assert "drones must be >= 1" in capsys.readouterr().err
    assert fleet_model.RAY_TESTED_ACTORS == 10_000


def test_a_camera_s_bytes_per_drone_can_replace_the_fitted_ones():
    m = fit([_report([2, 2])])
    p = project(m, 1000, 64.0, 64.0, mb_per_drone=1.5)
    rec = {lim.resource: lim.drones_per_node for lim in p.limits}["recorder (one per node)"]
    assert rec == math.floor(min(8000.0 / COST["msgs"], 15.0 / 1.5)) == 10
    assert p.breaks_first == "recorder (one per node)"
