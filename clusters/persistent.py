"""A persistent local Ray cluster: ``aerodaas up`` starts it once, ``aerodaas run`` attaches, ``aerodaas down``
stops it (issue 27, item 2).

``aerodaas up`` starts a daemon (``python -m aerodaas.clusters.persistent serve``, its own session) that runs one
Ray head node with ``ray.cluster_utils.Cluster``: loopback only (:func:`aerodaas.runtime.loopback.loopback_only`), token
authentication on (:func:`aerodaas.clusters.local.enable_token_auth`), labelled ``tier=edge`` and
``aerodaas/compute=local``, with its dashboard on 127.0.0.1 (Ray prestarts ``num_cpus`` workers when the driver
connects). The daemon writes
:func:`state_path` (``{"pid", "address", "dashboard", "session_dir"}``) once the node is up and removes it when it
stops; ``aerodaas down`` sends SIGTERM to that pid only, and the daemon stops the processes its node started
(``Cluster.shutdown``), never ``ray stop`` (which would stop every Ray of the machine).

:func:`attached_address` is what ``aerodaas run`` (without ``--address``) consults: the GCS address of a running
cluster of this kind, or None.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

__all__ = ["attached_address", "down", "read_state", "state_path", "up"]


def state_path() -> Path:
    """``$AERODAAS_STATE_DIR/cluster.json`` (default ``~/.aerodaas/cluster.json``)."""
    base = os.environ.get("AERODAAS_STATE_DIR") or os.path.join(os.path.expanduser("~"), ".aerodaas")
    return Path(base) / "cluster.json"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def read_state() -> dict[str, Any] | None:
    """The running cluster's state, or None (no file, unreadable, or its daemon is gone: the file is removed)."""
    p = state_path()
    try:
        st = json.loads(p.read_text())
        pid = int(st["pid"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if not _alive(pid):
        p.unlink(missing_ok=True)
        return None
    return st


def attached_address() -> str | None:
    """The GCS address (``127.0.0.1:PORT``) of the cluster ``aerodaas up`` started, if it is running."""
    st = read_state()
    return st.get("address") if st else None


def up(cpus: int = 3, timeout_s: float = 180.0) -> dict[str, Any]:
    """Start the cluster (or return the running one's state with ``"already": True``). Raises RuntimeError when the
    daemon exits or does not report ready within ``timeout_s`` seconds (its log path is named)."""
    st = read_state()
    if st:
        return {**st, "already": True}
    p = state_path()
    p.parent.mkdir(parents=True, exist_ok=True)
    logf = p.with_suffix(".log")
    with open(logf, "wb") as log:
        proc = subprocess.Popen([sys.executable, "-m", "aerodaas.clusters.persistent", "serve", str(int(cpus))],
                                stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True, close_fds=True)
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        st = read_state()
        if st and st.get("pid") == proc.pid:
            return {**st, "already": False, "log": str(logf)}
        if proc.poll() is not None:
            raise RuntimeError(f"aerodaas up: the cluster daemon exited ({proc.returncode}); see {logf}")
        time.sleep(0.2)
    proc.terminate()
    raise RuntimeError(f"aerodaas up: the cluster did not start within {timeout_s:g} s; see {logf}")


def down(timeout_s: float = 60.0) -> dict[str, Any] | None:
    """Stop the cluster ``up`` started (SIGTERM to its daemon, which stops its node's processes); None if none runs.
    Raises RuntimeError if the daemon is still alive after ``timeout_s`` seconds."""
    st = read_state()
    if not st:
        return None
    pid = int(st["pid"])
    os.kill(pid, signal.SIGTERM)
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        if not _alive(pid) or _zombie(pid):
            state_path().unlink(missing_ok=True)
            return st
        time.sleep(0.1)
    raise RuntimeError(f"aerodaas down: the cluster daemon (pid {pid}) did not stop within {timeout_s:g} s")


def _zombie(pid: int) -> bool:
    try:
        import psutil

        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except Exception:  # noqa: BLE001 - gone, or psutil missing
        return False


def _serve(cpus: int) -> None:
    """The daemon: start the head node, write the state file, wait for SIGTERM/SIGINT, stop the node."""
    import threading

    from ray.cluster_utils import Cluster

    from aerodaas.clusters.local import enable_token_auth
    from aerodaas.runtime.loopback import loopback_only

    enable_token_auth()
    loopback_only()  # kept: this process exists only to run the node
    from aerodaas.runtime.worker_memory import limit_malloc_arenas

    limit_malloc_arenas()  # the workers' C heap (aerodaas.runtime.worker_memory)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    cluster = Cluster(initialize_head=True, shutdown_at_exit=True, head_node_args={
        "num_cpus": cpus, "labels": {"tier": "edge", "aerodaas/compute": "local"},
        "include_dashboard": True, "dashboard_host": "127.0.0.1",
        "_system_config": {"worker_niceness": 0}})
    node = cluster.head_node
    st = {"pid": os.getpid(), "address": cluster.address, "session_dir": node.get_session_dir_path(),
          "dashboard": getattr(node, "webui_url", None) or "", "started": time.time()}
    tmp = state_path().with_suffix(".tmp")
    tmp.write_text(json.dumps(st))
    tmp.replace(state_path())
    print(f"aerodaas cluster up: {st}", flush=True)
    try:
        stop.wait()
    finally:
        cluster.shutdown()
        try:
            if json.loads(state_path().read_text()).get("pid") == os.getpid():
                state_path().unlink()
        except (OSError, ValueError):
            pass
        print("aerodaas cluster down", flush=True)


if __name__ == "__main__" and len(sys.argv) >= 2 and sys.argv[1] == "serve":
    _serve(int(sys.argv[2]) if len(sys.argv) > 2 else 3)
