"""The local Ray that ``aerodaas run`` starts (no ``--address``) is reachable from this machine only."""
from __future__ import annotations

import ipaddress
import os


def test_local_ray_listens_on_loopback_only(ray_session):
    """Every listening socket of the session's Ray processes (GCS, raylet, object manager, agents, workers) is on
    a loopback address, and the node registers as 127.0.0.1; the driver's process is left as it was (a later
    ``ray.init(address=...)`` to a real cluster must see the machine's address)."""
    import psutil
    import ray
    from ray._private import ray_constants

    from aerodaas.bench.procs import ray_processes

    assert ray.get_runtime_context().gcs_address.rsplit(":", 1)[0] == "127.0.0.1"
    assert {n["NodeManagerAddress"] for n in ray.nodes() if n["Alive"]} == {"127.0.0.1"}
    pids = {p.pid for p in ray_processes()} - {os.getpid()}
    listening = [c for c in psutil.net_connections("inet") if c.status == psutil.CONN_LISTEN and c.pid in pids]
    assert listening, "no listening socket found for the session's Ray processes"
    exposed = [(c.pid, c.laddr) for c in listening
               if not ipaddress.ip_address(c.laddr.ip.removeprefix("::ffff:")).is_loopback]
    assert not exposed, f"Ray processes listening beyond loopback: {exposed}"
    assert ray_constants.ENABLE_RAY_CLUSTER and "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER" not in os.environ
