"""``LocalCluster`` (bench fleet --edge-nodes, bench schedulers, cluster tests) listens on loopback only, as
``aerodaas run``'s local mode does: every listening socket of every process of the cluster."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.conftest import REPO

PROBE = r'''
import ipaddress, json, os, psutil, ray
from aerodaas.clusters.local import LocalCluster
from ray._private import ray_constants

with LocalCluster(cloud_nodes=1, edge_nodes=2) as lc:
    @ray.remote(num_cpus=0)
    def where():
        return ray.get_runtime_context().get_node_id()
    ray.get([where.options(label_selector={"tier": t}).remote() for t in ("edge", "cloud")])
    procs = psutil.Process(os.getpid()).children(recursive=True)
    pids = {p.pid for p in procs} | {os.getpid()}
    listening = [c for c in psutil.net_connections("inet") if c.status == psutil.CONN_LISTEN and c.pid in pids]
    out = {"nodes": sorted({n["NodeManagerAddress"] for n in ray.nodes() if n["Alive"]}),
           "n_nodes": sum(n["Alive"] for n in ray.nodes()),
           "listening": [[c.pid, c.laddr.ip, c.laddr.port] for c in listening]}
out["restored"] = ray_constants.ENABLE_RAY_CLUSTER and "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER" not in os.environ
print("RESULT " + json.dumps(out))
'''


@pytest.mark.cluster
def test_local_cluster_listens_on_loopback_only():
    p = subprocess.run([sys.executable, "-c", PROBE], cwd=REPO, capture_output=True, text=True, timeout=600)
    line = next((ln for ln in p.stdout.splitlines() if ln.startswith("RESULT ")), None)
    assert p.returncode == 0 and line, p.stdout[-2000:] + p.stderr[-3000:]
    out = json.loads(line[len("RESULT "):])
    assert out["n_nodes"] == 3 and out["nodes"] == ["127.0.0.1"], out
    assert len(out["listening"]) >= 6, out  # GCS, raylets, object managers, workers: found, not an empty list
    exposed = [c for c in out["listening"]
               if not ipaddress_is_loopback(c[1])]
    assert not exposed, f"LocalCluster processes listening beyond loopback: {exposed}"
    assert out["restored"], "the driver's process must see the machine's address again after shutdown"


def ipaddress_is_loopback(ip: str) -> bool:
    import ipaddress

    return ipaddress.ip_address(ip.removeprefix("::ffff:")).is_loopback
