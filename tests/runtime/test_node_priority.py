"""A run's own local Ray starts its raylet's two agents 5 below the driver's niceness, so that a loaded machine does
not starve them past Ray's fixed 15 s wait for their ports; the GCS, the raylet, the log monitor, the workers and the
driver, every thread of each, stay at the driver's niceness (``aerodaas.clusters.node_priority``). Read from /proc,
per thread, on a real local Ray started as ``aerodaas run`` starts it."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from aerodaas.clusters.node_priority import AGENT_NICE_DELTA, agents_ahead, may_lower_niceness

ROOT = Path(__file__).resolve().parents[2]

#: starts a local Ray through aerodaas.runtime.ray_start, starts an actor, prints the niceness of every thread of
#: the driver, the actor and each of the driver's descendants (by command line) as JSON
_PROBE = r"""
import json, os
import ray
from aerodaas.runtime.ray_start import init_ray
from aerodaas.clusters import reaper
from tests.cluster.node_nices import thread_nices as nices

init_ray(None)

@ray.remote(num_cpus=0)
class Probe:
    def nices(self):
        return os.getpid(), nices(os.getpid())

pid, actor = ray.get(Probe.remote().nices.remote(), timeout=120)
procs = {}
for p in reaper.descendants(os.getpid()):
    try:
        cmd = open(f"/proc/{p}/cmdline", "rb").read().replace(b"\0", b" ").decode(errors="replace")
        procs[p] = [cmd, nices(p)]
    except OSError:
        pass
print(json.dumps({"driver": nices(os.getpid()), "actor": actor, "actor_pid": pid, "procs": procs}))
ray.shutdown()
"""


def test_the_agents_start_ahead_of_the_load_and_everything_else_at_the_drivers_niceness():
    env = {k: v for k, v in os.environ.items() if k not in ("AERODAAS_NODE_NICE", "RAY_ADDRESS")}
    r = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, timeout=600, cwd=ROOT, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    mine = os.getpriority(os.PRIO_PROCESS, 0)
    agent = mine + AGENT_NICE_DELTA if may_lower_niceness() else mine
    by_kind: dict[str, list] = {}
    for pid, (cmd, nices) in out["procs"].items():
        kind = next((k for k in ("gcs_server", "raylet", "DashboardAgent", "RuntimeEnvAgent", "log_monitor")
                     if k in cmd), "worker" if cmd.startswith("ray::") else None)
        if kind:
            by_kind.setdefault(kind, []).append(nices)
    assert {"gcs_server", "raylet", "DashboardAgent", "RuntimeEnvAgent", "log_monitor", "worker"} <= set(by_kind), out
    for kind in ("DashboardAgent", "RuntimeEnvAgent"):
        assert by_kind[kind] == [[agent]], (kind, by_kind[kind], agent)
    for kind in ("gcs_server", "raylet", "log_monitor"):
        assert by_kind[kind] == [[mine]], (kind, by_kind[kind], mine)
    # every thread of every worker (the actor's and the idle ones) and of the driver at the driver's niceness
    assert out["actor"] == [mine] and all(n == [mine] for n in by_kind["worker"]), (out["actor"], by_kind["worker"])
    assert out["driver"] == [mine], out["driver"]


def test_turned_off_it_changes_nothing(monkeypatch):
    from ray._private import services

    build = services._build_python_executable_command_memory_profileable
    monkeypatch.setenv("AERODAAS_NODE_NICE", "0")
    with agents_ahead() as on:
        assert not on and services._build_python_executable_command_memory_profileable is build
    monkeypatch.delenv("AERODAAS_NODE_NICE")
    with agents_ahead() as on:  # in effect: only the agents' commands change, and Ray's module is restored after
        cmd = services._build_python_executable_command_memory_profileable("dashboard_agent", "/tmp")
        other = services._build_python_executable_command_memory_profileable("dashboard", "/tmp")
        assert (cmd[1:3] == ["-n", str(AGENT_NICE_DELTA)]) == on == may_lower_niceness()
        assert other == build("dashboard", "/tmp")
    assert services._build_python_executable_command_memory_profileable is build
