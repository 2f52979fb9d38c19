"""Runs an application on a fresh :class:`~aerodaas.clusters.local.LocalCluster` (its own Ray, separate raylets per
node) and prints one JSON line: ``python tests/cluster/cluster_runtime_app.py MODE OUT_DIR``. Used by
``tests/runtime/test_runtime_actors.py`` as a subprocess, so the test session's own Ray is left alone.

* ``placement``: two ``tier=edge`` nodes (labels ``aerodaas/site: a`` / ``b``), one ``tier=cloud`` node; six drones,
  three flying from each edge compute; a detector deployed on each edge compute, scheduled per frame by DEMS (a
  dispatcher per edge compute, cloud executors on the cloud node). Reports where Ray's GCS says every actor of the
  run is (node labels), read while the run is up.
* ``node_loss``: two edge nodes; drone ``d00`` flies from the head's compute, ``d01`` from the other node's; once
  both fly, the other node is killed. Reports the mission result and the recording's path.
"""
from __future__ import annotations

import json
import os
import sys
import threading
import time


def _cfg(n: int, sites: list[str], hover_s: float, scheduler: dict | None = None) -> dict:
    robots = []
    for i in range(n):
        robots.append({"id": f"d{i:02d}", "compute": f"edge-{sites[i % len(sites)]}", "takeoff_altitude": 3.0,
                       "limits": {"max_speed": 3.0, "max_vertical_speed": 2.0, "max_acceleration": 3.0},
                       "sensors": [{"id": "cam", "type": "camera", "properties": {
                           "width": 160, "height": 120, "hfov_deg": 78, "fps": 5, "pitch_deg": 90}}]})
    cfg = {"name": "cluster", "robots": robots, "actor_restart_timeout_s": 8.0,
           "compute": [{"id": f"edge-{s}", "tier": "edge", "labels": {"aerodaas/site": s}} for s in sites]
           + [{"id": "cloud", "tier": "cloud"}],
           "world": {"ground": {"seed": 2, "metres_per_pixel": 0.05, "size_m": 80}},
           "simulation": {"speedup": 2.0}}
    if scheduler:
        cfg["analytics_scheduler"] = scheduler
    return cfg


def _survey(env, drone, sched, hover_s: float, i: int) -> None:
    from aerodaas import AeroListData, PriorityQueue, Waypoint

    wps = [Waypoint(id=f"w{k}", x=3.0 * i + (2.0 if k % 2 else 0.0), y=2.0 * k, z=3.0, hover_duration=hover_s)
           for k in range(3)]
    drone.navigate(sched.generate_navigation(PriorityQueue(AeroListData(wps), priority=2)))


def _actors_by_node() -> list[dict]:
    """Every live actor of the cluster with its name, class and its node's labels (from Ray's GCS)."""
    import ray
    from ray._private import state

    labels = {n["NodeID"]: n.get("Labels", {}) for n in ray.nodes() if n.get("Alive")}
    out = []
    for a in state.actors().values():
        if a.get("State") != "ALIVE":
            continue
        node = (a.get("Address") or {}).get("NodeID")
        out.append({"name": a.get("Name"), "class": a.get("ActorClassName"), "node": node,
                    "labels": labels.get(node, {})})
    return out


def placement(out_dir: str) -> dict:
    from aerodaas import Environment, NearestNeighborScheduler
    from aerodaas.runtime.options import RunOptions
    from aerodaas.bench.pipeline import FixedCostDetector
    from aerodaas.clusters.local import LocalCluster
    from aerodaas.config import parse_environment_config

    qos = {"deadline_ms": 400, "edge_ms": 20, "cloud_ms": 60, "benefit": 100, "edge_cost": 1, "cloud_cost": 5}
    cfg = _cfg(6, ["a", "b"], 1.0, {"name": "DEMS", "models": {"det-a": qos, "det-b": qos}})
    with LocalCluster(cloud_nodes=1, edge_nodes=2, edge_labels=[{"aerodaas/site": "a"}, {"aerodaas/site": "b"}], worker_niceness=0,
                      edge_cpus=2, cloud_cpus=2) as lc:
        env = Environment(parse_environment_config(cfg))
        sched = NearestNeighborScheduler(env)
        env.set_trajectory_scheduler(sched)
        dets = {}
        for s in ("a", "b"):
            d = FixedCostDetector(cost_ms=5.0)
            d.name = f"det-{s}"
            d.deploy(env.get_compute_resource_by_id(f"edge-{s}"))
            dets[s] = d
        for i, drone in enumerate(env.get_env_robots()):
            dets["ab"[i % 2]].analyse(drone.get_sensor_by_id("cam").get_data_stream())
            _survey(env, drone, sched, 1.0, i)
        opts = RunOptions(progress=False, address=lc.address, run_id="place")
        seen: dict = {}
        env.get_robot_by_id("d00").on_mission_start(lambda r: seen.update(actors=_actors_by_node()))
        res = env.start_mission(timeout=60, options=opts)
        return {"outcome": res.outcome, "actors": seen.get("actors", []),
                "outcomes": {k: v.get("outcome") for k, v in res.robots.items()},
                "scheduler": {k: res.stats.get("analytics_scheduler", {}).get(k) for k in ("submitted", "tiers")}}


def node_loss(out_dir: str) -> dict:
    from aerodaas import Environment, NearestNeighborScheduler
    from aerodaas.runtime.options import RunOptions
    from aerodaas.runtime.report import format_summary
    from aerodaas.clusters.local import LocalCluster
    from aerodaas.config import parse_environment_config

    cfg = _cfg(2, ["a", "b"], 4.0)
    rec = os.path.join(out_dir, "node_loss.mcap")
    with LocalCluster(cloud_nodes=0, edge_nodes=2, edge_labels=[{"aerodaas/site": "a"}, {"aerodaas/site": "b"}],
                      worker_niceness=0) as lc:
        env = Environment(parse_environment_config(cfg))
        sched = NearestNeighborScheduler(env)
        env.set_trajectory_scheduler(sched)
        for i, drone in enumerate(env.get_env_robots()):
            _survey(env, drone, sched, 4.0, i)
        opts = RunOptions(progress=False, address=lc.address, run_id="loss", record=rec)
        killed: dict = {}

        def kill_later(robot) -> None:
            def go() -> None:
                import ray

                h = ray.get_actor("aerodaas/loss/drone/d01")
                for _ in range(200):  # until d01 is in the air, on its way
                    from aerodaas.actors.drone.component import DroneComponent

                    st = ray.get(h.call.remote("d01/drone", DroneComponent.status))
                    if st["state"] in ("NAVIGATING", "WAYPOINT_HOLD"):
                        break
                    time.sleep(0.2)
                killed["t"] = st["t"]
                killed["node"] = lc.remove_edge_node(1)

            threading.Thread(target=go, daemon=True).start()

        env.get_robot_by_id("d00").on_mission_start(kill_later)
        res = env.start_mission(timeout=120, options=opts)
        return {"outcome": res.outcome, "killed": killed, "recording": rec,
                "robots": {k: {"outcome": v.get("outcome"), "visited": v.get("visited"), "error": v.get("error")}
                           for k, v in res.robots.items()},
                "summary": format_summary(res)}


if __name__ == "__main__":
    mode, out = sys.argv[1], sys.argv[2]
    result = {"placement": placement, "node_loss": node_loss}[mode](out)
    print("RESULT " + json.dumps(result, default=str), flush=True)
