"""One recorder per node on a fresh :class:`~aerodaas.clusters.local.LocalCluster` (its own Ray, separate raylets
per node): ``python tests/cluster/cluster_recorders_app.py OUT_DIR [local]`` prints one JSON line. Used by
``tests/cluster/test_node_recorders_cluster.py`` as a subprocess, so the test session's own Ray is left alone. ``local``:
the same run on a single-node local Ray of its own (labels are not required there: both node recorders run on
this node), for the development tier.

Two ``tier=edge`` nodes (labels ``aerodaas/site: a`` / ``b``); drone ``d00`` flies from compute ``edge-a``, ``d01``
from ``edge-b``, each with a camera; ``recording.per_node: true``, recorded to ``OUT_DIR/run.mcap`` with a live
view on a free loopback port. While the run is up, a Foxglove protocol client (``tests/liveview/foxglove_ws_client.py``)
gathers both drones' odometry from the live view, and Ray's GCS says on which node every recorder actor is."""
from __future__ import annotations

import json
import os
import socket
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def _cluster(local: bool) -> Iterator[str | None]:
    """The address of a two-edge-node LocalCluster (labels ``aerodaas/site`` a / b), or None (``local``: the run
    starts its own single-node Ray)."""
    if local:
        yield None
        return
    from aerodaas.clusters.local import LocalCluster

    with LocalCluster(cloud_nodes=0, edge_nodes=2, edge_labels=[{"aerodaas/site": "a"}, {"aerodaas/site": "b"}],
                      worker_niceness=0) as lc:
        yield lc.address


def main(out_dir: str, local: bool = False) -> dict:
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
    from aerodaas import AeroListData, Environment, NearestNeighborScheduler, PriorityQueue, Waypoint
    from aerodaas.config import parse_environment_config
    from aerodaas.runtime.options import RunOptions
    from aerodaas.runtime.report import format_summary
    from tests.cluster.cluster_runtime_app import _actors_by_node, _cfg
    from tests.liveview.foxglove_ws_client import collect

    cfg = {**_cfg(2, ["a", "b"], 2.0), "recording": {"per_node": True}}
    rec = os.path.join(out_dir, "run.mcap")
    port = _free_port()
    live: dict = {}
    with _cluster(local) as address:
        env = Environment(parse_environment_config(cfg))
        sched = NearestNeighborScheduler(env)
        env.set_trajectory_scheduler(sched)
        for i, drone in enumerate(env.get_env_robots()):
            wps = [Waypoint(id=f"w{k}", x=3.0 * i + (2.0 if k % 2 else 0.0), y=2.0 * k, z=3.0, hover_duration=2.0)
                   for k in range(3)]
            drone.navigate(sched.generate_navigation(PriorityQueue(AeroListData(wps), priority=2)))

        def watch(_robot) -> None:
            live["actors"] = _actors_by_node()
            want = {"/d00/odometry": 5, "/d01/odometry": 5, "/d00/camera/cam": 2, "/d01/camera/cam": 2}
            threading.Thread(target=lambda: live.update(got=collect(f"ws://127.0.0.1:{port}", want, timeout_s=90)),
                             daemon=True).start()

        env.get_robot_by_id("d00").on_mission_start(watch)
        opts = RunOptions(progress=False, address=address, run_id="pernode", record=rec,
                                  live=f"127.0.0.1:{port}")
        res = env.start_mission(timeout=120, options=opts)
    got = live.get("got") or {}
    return {"outcome": res.outcome, "recording": rec, "accounting": res.recording_accounting,
            "robots": {k: v.get("outcome") for k, v in res.robots.items()},
            "actors": live.get("actors", []),
            "live_channels": sorted(got.get("channels", {})),
            "live_counts": {t: len(m) for t, m in (got.get("messages") or {}).items()},
            "nodes": res.recording_nodes, "summary": format_summary(res)}


if __name__ == "__main__":
    print("RESULT " + json.dumps(main(sys.argv[1], sys.argv[2:] == ["local"]), default=str), flush=True)
