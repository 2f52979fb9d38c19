"""``aerodaas up`` / ``aerodaas down``: one loopback-only, token-authenticated Ray head labelled
``tier=edge``; ``down`` stops exactly the processes ``up`` started. Uses a private ``AERODAAS_STATE_DIR`` so it never
meets a cluster the user started."""
from __future__ import annotations

import ipaddress
import json
import os
import subprocess
import sys

import psutil
import pytest

from tests.cluster.node_nices import expected_agent_nice, node_nices
from tests.conftest import REPO


def _aerodaas(env: dict, *args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "aerodaas.cli", *args], cwd=REPO, env=env, capture_output=True,
                          text=True, timeout=timeout)


@pytest.mark.cluster
def test_up_starts_one_loopback_head_and_down_stops_only_its_processes(tmp_path):
    env = dict(os.environ, AERODAAS_STATE_DIR=str(tmp_path))
    p = _aerodaas(env, "up", "--cpus", "1")
    assert p.returncode == 0 and "started" in p.stdout, p.stdout + p.stderr
    st = json.loads((tmp_path / "cluster.json").read_text())
    try:
        daemon = psutil.Process(st["pid"])
        procs = [daemon, *daemon.children(recursive=True)]
        pids = {q.pid for q in procs}
        assert len(pids) >= 3, procs  # the daemon, the GCS, the raylet (and agents, dashboard)
        # the raylet's agents ahead of the load (aerodaas.clusters.node_priority), the rest at the daemon's niceness
        nices, daemon_nice = node_nices(st["pid"]), daemon.nice()
        assert nices["raylet"] == [[daemon_nice]] and nices["gcs_server"] == [[daemon_nice]], nices
        assert nices["DashboardAgent"] == nices["RuntimeEnvAgent"] == [[expected_agent_nice(daemon_nice)]], nices
        listening = [c for c in psutil.net_connections("inet") if c.status == psutil.CONN_LISTEN and c.pid in pids]
        assert listening and all(ipaddress.ip_address(c.laddr.ip.removeprefix("::ffff:")).is_loopback
                                 for c in listening), listening
        assert st["address"].startswith("127.0.0.1:")
        again = _aerodaas(env, "up")
        assert again.returncode == 0 and "already running" in again.stdout and str(st["pid"]) in again.stdout
        # a driver attaches with the token (and, as the node is loopback-only, as 127.0.0.1: Ray's local-only switch)
        # and sees the node's labels
        probe = ("import ray; from aerodaas.clusters.local import enable_token_auth; enable_token_auth(); "
                 "from aerodaas.clusters.loopback import loopback_only; loopback_only(); "
                 f"ray.init(address={st['address']!r}, logging_level='error'); "
                 "import json; print('LABELS', json.dumps([n['Labels'] for n in ray.nodes() if n['Alive']]))")
        q = subprocess.run([sys.executable, "-c", probe], cwd=REPO, env=env, capture_output=True, text=True,
                           timeout=180)
        line = next(ln for ln in q.stdout.splitlines() if ln.startswith("LABELS "))
        (labels,) = json.loads(line[len("LABELS "):])
        assert labels["tier"] == "edge" and labels["aerodaas/compute"] == "local"
    finally:
        d = _aerodaas(env, "down")
    assert d.returncode == 0 and "stopped" in d.stdout, d.stdout + d.stderr
    _, alive = psutil.wait_procs(procs, timeout=60)
    assert not [q for q in alive if q.status() != psutil.STATUS_ZOMBIE], alive
    assert not (tmp_path / "cluster.json").exists()
    assert "no local cluster" in _aerodaas(env, "down").stdout


@pytest.mark.cluster
def test_up_beside_another_dashboard_on_8265_binds_the_next_free_port(tmp_path):
    """Another Ray on the machine (a developer's `ray start`, a test's LocalCluster) holds 127.0.0.1:8265: `aerodaas
    up` still starts, its dashboard on another port, which the state file and its own line name (it failed with
    "Failed to bind to 127.0.0.1:8265" before, 2026-11-26)."""
    import socket

    holder = socket.socket()
    try:
        holder.bind(("127.0.0.1", 8265))
        holder.listen(1)
    except OSError:  # some other process holds it already: the situation this test is about
        holder.close()
        holder = None
    env = dict(os.environ, AERODAAS_STATE_DIR=str(tmp_path))
    try:
        p = _aerodaas(env, "up", "--cpus", "1")
        assert p.returncode == 0 and "started" in p.stdout, p.stdout + p.stderr
        dashboard = json.loads((tmp_path / "cluster.json").read_text())["dashboard"]
        host, port = dashboard.rsplit(":", 1)
        assert host.removeprefix("http://") == "127.0.0.1" and int(port) != 8265, dashboard
        assert f"dashboard http://{dashboard}" in p.stdout or f"dashboard {dashboard}" in p.stdout, p.stdout
    finally:
        d = _aerodaas(env, "down")
        if holder is not None:
            holder.close()
    assert d.returncode == 0 and "stopped" in d.stdout, d.stdout + d.stderr
