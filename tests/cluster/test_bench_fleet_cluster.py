"""``aerodaas bench fleet --edge-nodes 2`` on a local two-node cluster: the drones run on both
nodes — Ray's GCS places a drone actor on each node's raylet (node ids from Ray's state API) — and the per-node
accounting adds up to the fleet's. The benchmark runs as a subprocess (its own cluster; the test session's Ray is
left alone); everything is read from its JSON report."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.cluster
def test_bench_fleet_on_two_edge_nodes_places_a_drone_on_each_and_accounts_per_node():
    p = subprocess.run([sys.executable, "-m", "aerodaas.cli", "bench", "fleet", "--edge-nodes", "2", "--drones", "2",
                        "--duration", "8", "--json"], cwd=ROOT, capture_output=True, text=True, timeout=1200,
                       env=dict(os.environ))
    assert p.returncode == 0, (p.stdout[-2000:], p.stderr[-3000:])
    rep = json.loads(p.stdout)
    (row,) = rep["results"]
    nodes = row["nodes"]

    # two raylets, a drone on each: the GCS's drone actors by node, and each robot on its compute's node
    assert len(nodes) == 2 and len({n["node_id"] for n in nodes}) == 2 and [n["head"] for n in nodes] == [True, False]
    assert [n["drones"] for n in nodes] == [1, 1], nodes
    assert [n["robots"] for n in nodes] == [["d00"], ["d01"]]
    assert nodes[0]["drone_actors"][0].endswith("/drone/d00") and nodes[1]["drone_actors"][0].endswith("/drone/d01")
    assert row["gcs_actor_classes"] == {"DroneActor": 2, "RecorderActor": 3}  # a recorder per node + the run's
    assert sum(n["gcs_actors"] for n in nodes) == row["gcs_actors"] == 5

    # the accounting is complete: the nodes' counts add up to the fleet's, nothing recorded was lost
    for key in ("ticks", "missed_ticks", "camera_ticks", "frames_analysed"):
        assert sum(n[key] for n in nodes) == row[key], key
    assert all(n["ticks"] > 0 and n["camera_ticks"] > 0 for n in nodes), nodes
    assert row["recording_accounting_read"] and row["recording_lost"] == 0, row
    assert all(n["recorder"]["messages"] > 0 for n in nodes), [n["recorder"] for n in nodes]
    assert row["outcomes"] == ["timeout"]  # the fleet flies its looping survey until --duration ends

    # the costs were measured inside the flight on each node: drone actor CPU and PSS, the head's GCS and driver
    assert row["window"]["complete"] and row["window"]["error"] is None, row["window"]
    for n in nodes:
        assert n["cpu_s_per_sim_s"]["drone_actors"] > 0 and n["pss_mb_per_drone_actor"] > 0, n
        assert n["processes"]["raylet"] == 1 and n["processes"]["drone_actors"] == 1, n["processes"]
    assert nodes[0]["processes"]["gcs"] == 1 and "gcs" not in nodes[1]["processes"]
    assert nodes[0]["processes"]["driver"] == 1
