"""A run's own local Ray starts its node processes (GCS, raylet, its agents, the log monitor) 5 below the driver's
niceness, so that a loaded machine does not starve the raylet's agents past Ray's fixed 15 s wait for their ports;
the workers, every thread of them, and the driver's own threads stay at the driver's niceness
(``aerodaas.clusters.node_priority``). Read from /proc, per thread, on a real local Ray started as ``aerodaas run``
starts it."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from pathlib import Path

from aerodaas.clusters.node_priority import NODE_NICE_DELTA, raised_node_priority

ROOT = Path(__file__).resolve().parents[2]

#: starts a local Ray through aerodaas.runtime.ray_start, starts an actor, prints the niceness of every thread of
#: the driver, the actor and each of the driver's descendants (by command line) as JSON
_PROBE = r"""
import json, os, threading
import ray
from aerodaas.runtime.ray_start import init_ray
from aerodaas.clusters import reaper

def nices(pid):
    out = set()
    for tid in os.listdir(f"/proc/{pid}/task"):
        try:
            out.add(int(open(f"/proc/{pid}/task/{tid}/stat").read().rsplit(")", 1)[1].split()[16]))
        except OSError:
            pass
    return sorted(out)

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


def _may_lower_niceness() -> bool:
    """Whether this process may lower a niceness (CAP_SYS_NICE): tried on a thread of its own."""
    out: list[bool] = []

    def attempt() -> None:
        tid = threading.get_native_id()
        nice = os.getpriority(os.PRIO_PROCESS, tid)
        try:
            os.setpriority(os.PRIO_PROCESS, tid, nice - 1)
            out.append(True)
        except OSError:
            out.append(False)

    t = threading.Thread(target=attempt)
    t.start()
    t.join()
    return out[0]


def test_the_node_starts_ahead_of_the_load_and_the_workers_and_driver_stay_at_the_drivers_niceness():
    env = {k: v for k, v in os.environ.items() if k not in ("AERODAAS_NODE_NICE", "RAY_ADDRESS")}
    r = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, timeout=600, cwd=ROOT, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    mine = os.getpriority(os.PRIO_PROCESS, 0)
    node = mine + NODE_NICE_DELTA if _may_lower_niceness() else mine
    by_kind: dict[str, list] = {}
    for pid, (cmd, nices) in out["procs"].items():
        kind = next((k for k in ("gcs_server", "raylet", "DashboardAgent", "RuntimeEnvAgent", "log_monitor")
                     if k in cmd), "worker" if cmd.startswith("ray::") else None)
        if kind:
            by_kind.setdefault(kind, []).append(nices)
    assert {"gcs_server", "raylet", "DashboardAgent", "RuntimeEnvAgent", "log_monitor", "worker"} <= set(by_kind), out
    for kind in ("gcs_server", "raylet", "DashboardAgent", "RuntimeEnvAgent", "log_monitor"):
        assert by_kind[kind] == [[node]], (kind, by_kind[kind], node)
    # every thread of every worker (the actor's and the idle ones) and of the driver at the driver's niceness
    assert out["actor"] == [mine] and all(n == [mine] for n in by_kind["worker"]), (out["actor"], by_kind["worker"])
    assert out["driver"] == [mine], out["driver"]


def test_turned_off_it_changes_nothing(monkeypatch):
    monkeypatch.setenv("AERODAAS_NODE_NICE", "0")
    monkeypatch.delenv("AERODAAS_WORKER_NICE", raising=False)
    tid = threading.get_native_id()
    before = os.getpriority(os.PRIO_PROCESS, tid)
    with raised_node_priority() as on:
        assert not on and os.getpriority(os.PRIO_PROCESS, tid) == before
    assert "AERODAAS_WORKER_NICE" not in os.environ
