"""GPU execution providers on a fresh local cluster: ``python tests/perception/cluster_gpu_app.py OUT_DIR`` starts a
:class:`~aerodaas.clusters.local.LocalCluster` (with Ray's dashboard, for its state API) whose head (``tier=edge``)
declares no GPU and whose second ``tier=edge`` node declares one logical GPU (this machine has no real one), then
runs ``aerodaas run`` on it (``--address``) with an app whose detector asks for the CUDA provider. At mission start
the app writes the run's actors as Ray's state API lists them (``ray.util.state.list_actors``: name, node id,
required resources). Then the same app with the provider required (no CPU fallback). Prints one line
``RESULT {json}``: each run's exit code and output, the first run's actors, the node ids (head, GPU node) and its
recording's path. Used by ``tests/perception/test_perception_providers.py`` as a subprocess, so the
test session's own Ray is left alone."""
from __future__ import annotations

import json
import os
import subprocess
import sys

APP = '''
import json
from aerodaas import *
from aerodaas.perception.providers import Providers

env = Environment({env!r})
drone = env.get_robot_by_id("d1")
det = ObjectDetector("yolox_nano", classes=["car"], providers={providers})
det.deploy(env.get_compute_resource_by_id("edge"))
det.analyse(drone.get_sensor_by_id("cam").get_data_stream())
drone.navigate(AeroNavigation(NavigationType.DISTANCE_DRIVEN,
                              [Waypoint(id="a", x=1.0, y=0.0, z=3.0, hover_duration=1.0)]))


def placed(robot):
    import ray
    from ray.util.state import list_actors

    # this run's cluster's dashboard (other Ray instances may run on this machine)
    dashboard = "http://" + ray._private.worker.get_dashboard_url()
    rows = [{{"name": a.name, "node_id": a.node_id, "state": a.state,
              "required_resources": dict(a.required_resources or {{}})}}
            for a in list_actors(address=dashboard, filters=[("state", "=", "ALIVE")], detail=True, limit=1000)]
    with open({actors!r}, "w") as f:
        json.dump(rows, f)


drone.on_mission_start(placed)
drone.start_mission()
'''


def main(out_dir: str) -> dict:
    from aerodaas.clusters.local import LocalCluster

    env = os.path.join(out_dir, "env.json")
    with open(env, "w") as f:
        json.dump({"name": "gpu", "compute": [{"id": "edge", "tier": "edge"}],
                   "robots": [{"id": "d1", "takeoff_altitude": 3.0, "sensors": [{"id": "cam", "type": "camera",
                               "properties": {"width": 160, "height": 120, "fps": 5, "pitch_deg": 90}}]}],
                   "simulation": {"speedup": 2.0}}, f)
    actors, rec, app = (os.path.join(out_dir, n) for n in ("actors.json", "gpu.mcap", "gpu_app.py"))
    with open(app, "w") as f:
        f.write(APP.format(env=env, actors=actors, providers='["CUDAExecutionProvider", "CPUExecutionProvider"]'))
    required = os.path.join(out_dir, "required_app.py")
    with open(required, "w") as f:  # no fallback: its actor cannot start on a node without the provider
        f.write(APP.format(env=env, actors=os.path.join(out_dir, "required_actors.json"),
                           providers='Providers(names=["CUDAExecutionProvider"], required=True)'))
    with LocalCluster(cloud_nodes=0, edge_cpus=2, connect=False, head_gpus=0, dashboard=True) as lc:
        gpu_node = lc.add_edge_node(num_gpus=1)
        lc.cluster.wait_for_nodes()
        def run(path: str, run_id: str, *extra: str) -> subprocess.CompletedProcess:
            return subprocess.run([sys.executable, "-m", "aerodaas.cli", "run", path, "--address", lc.address, *extra,
                                   "--quiet"], capture_output=True, text=True, timeout=300,
                                  env={**os.environ, "AERODAAS_RUN_ID": run_id})

        p = run(app, "gpu", "--record", rec)
        placed = json.load(open(actors)) if os.path.isfile(actors) else None
        q = run(required, "gpureq")
        return {"returncode": p.returncode, "stdout": p.stdout[-4000:], "stderr": p.stderr[-4000:],
                "actors": placed, "head": lc.edge_node.node_id, "gpu_node": gpu_node.node_id, "recording": rec,
                "required": {"returncode": q.returncode, "stdout": q.stdout[-4000:], "stderr": q.stderr[-4000:]}}


if __name__ == "__main__":
    print("RESULT " + json.dumps(main(sys.argv[1]), default=str), flush=True)
