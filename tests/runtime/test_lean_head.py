"""A run's own local Ray (``aerodaas.runtime.ray_start.init_ray``, as ``aerodaas run`` starts it when no cluster
is attached): without ``--dashboard`` its head starts neither the autoscaler monitor nor the dashboard's API server
(``aerodaas.clusters.lean_head``), while the raylet, its agents and the log monitor still start and the actors
run; with ``--dashboard`` everything starts and Ray's state API lists the run's actors. Each case is a fresh
driver process (a real Ray), identified by the command lines of the driver's descendants."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

#: a driver that starts Ray as a run does, creates a named actor, then prints the command lines of its own
#: descendants and, with the dashboard, what the state API lists (JSON on the last line)
DRIVER = """
import json, os, sys
import psutil
from aerodaas.runtime.ray_start import init_ray, shutdown_ray
dashboard = sys.argv[1] == "dashboard"
init_ray(None, dashboard=dashboard)
import ray
@ray.remote(num_cpus=0)
class Probe:
    def pid(self):
        return os.getpid()
probe = Probe.options(name="lean-head-probe").remote()
answered = ray.get(probe.pid.remote(), timeout=600) > 0
cmds = [" ".join(p.cmdline()) for p in psutil.Process().children(recursive=True) if p.is_running()]
listed = []
if dashboard:
    from ray.util.state import list_actors
    url = ray.get_runtime_context().worker.node.webui_url
    listed = [a.class_name for a in list_actors(address="http://" + url, limit=1000, timeout=120)]
shutdown_ray()
print(json.dumps({"answered": answered, "cmds": cmds, "listed": listed}))
"""

MONITOR = "autoscaler/_private/monitor.py"
API_SERVER = "dashboard/dashboard.py"
ALWAYS = ("gcs_server", "raylet", "dashboard/agent.py", "runtime_env/agent/main.py", "log_monitor.py")


def _run_driver(tmp_path, mode: str, **env_extra: str) -> dict:
    env = {**os.environ, "AERODAAS_NO_ATTACH": "1", "RAY_TMPDIR": str(tmp_path),
           # a loaded machine may take long to start the dashboard; Ray gives it 60 s by default, then the run
           # goes on without it
           "RAY_DASHBOARD_STARTUP_TIMEOUT_S": "600", **env_extra}
    if "AERODAAS_LEAN_HEAD" not in env_extra:
        env.pop("AERODAAS_LEAN_HEAD", None)
    out = subprocess.run([sys.executable, "-c", DRIVER, mode], cwd=ROOT, capture_output=True, text=True,
                         timeout=900, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def _started(cmds: list[str], part: str) -> bool:
    return any(part in c for c in cmds)


def test_a_run_without_dashboard_starts_no_monitor_and_no_api_server_and_its_actors_run(tmp_path):
    got = _run_driver(tmp_path, "plain")
    assert got["answered"]
    missing = [p for p in ALWAYS if not _started(got["cmds"], p)]
    assert not missing, (missing, got["cmds"])
    assert not _started(got["cmds"], MONITOR), got["cmds"]
    assert not _started(got["cmds"], API_SERVER), got["cmds"]


def test_the_lean_head_can_be_turned_off(tmp_path):
    got = _run_driver(tmp_path, "plain", AERODAAS_LEAN_HEAD="0")
    assert got["answered"]
    assert _started(got["cmds"], MONITOR) and _started(got["cmds"], API_SERVER), got["cmds"]


@pytest.mark.slow
def test_a_run_with_dashboard_starts_everything_and_the_state_api_lists_its_actors(tmp_path):
    got = _run_driver(tmp_path, "dashboard")
    assert got["answered"]
    assert _started(got["cmds"], MONITOR) and _started(got["cmds"], API_SERVER), got["cmds"]
    assert "Probe" in got["listed"], got["listed"]


def test_the_block_restores_rays_node_and_changes_nothing_when_turned_off(monkeypatch):
    from ray._private.node import Node

    from aerodaas.clusters.lean_head import LEFT_OUT, without_monitor_and_api_server

    before = {name: getattr(Node, name) for name in LEFT_OUT}
    with without_monitor_and_api_server() as on:
        assert on
        assert all(getattr(Node, name) is not before[name] for name in LEFT_OUT)
    assert {name: getattr(Node, name) for name in LEFT_OUT} == before
    monkeypatch.setenv("AERODAAS_LEAN_HEAD", "0")
    with without_monitor_and_api_server() as on:
        assert not on
        assert {name: getattr(Node, name) for name in LEFT_OUT} == before
