"""A persistent local Ray cluster: ``aerodaas up`` starts it once, ``aerodaas run`` attaches, ``aerodaas down``
stops it.

``aerodaas up`` starts a daemon (``python -m aerodaas.clusters.persistent serve``, its own session) that runs one
Ray head node with ``ray.cluster_utils.Cluster``: loopback only (:func:`aerodaas.clusters.loopback.loopback_only`), token
authentication on (:func:`aerodaas.clusters.local.enable_token_auth`), labelled ``tier=edge`` and
``aerodaas/compute=local``, with its dashboard on 127.0.0.1 (Ray prestarts ``num_cpus`` workers when the driver
connects). The daemon writes
:func:`state_path` (``{"pid", "address", "dashboard", "session_dir"}``) once the node is up and removes it when it
stops; ``aerodaas down`` sends SIGTERM to that pid only, and the daemon stops the processes its node started
(``Cluster.shutdown``), never ``ray stop`` (which would stop every Ray of the machine).

The daemon keeps ``warm_workers`` idle Python workers with the framework imported
(:mod:`aerodaas.clusters.warm_pool`), so that a run's actors start in processes that already run. The state file then
also holds ``warm_workers``, ``warm_idle`` (idle workers at the last look), ``code_fingerprint`` (of the framework's
code the warm workers imported), ``package_roots`` (where that code is) and ``sys_path`` (the import path the
node's workers share with the daemon).

:func:`attached_address` is what ``aerodaas run`` (without ``--address``) consults: the GCS address of a running
cluster of this kind, or None.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from aerodaas.clusters import reaper
from aerodaas.clusters.log_monitor import lean_log_monitor
from aerodaas.clusters.node_logs import default_temp_dir, failed_start_report
from aerodaas.clusters.node_priority import agents_ahead
from aerodaas.clusters.state_folder import state_dir

__all__ = ["attached_address", "await_fresh_workers", "down", "importable_by_cluster", "not_on_cluster_path",
           "read_state", "state_path", "up"]


def state_path() -> Path:
    """``$AERODAAS_STATE_DIR/cluster.json`` (default ``~/.aerodaas/cluster.json``)."""
    return Path(state_dir()) / "cluster.json"


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


#: idle workers kept warm by default: a drone, an analytics, the recorder and one spare
DEFAULT_WARM_WORKERS = 4


def importable_by_cluster(path: str, st: dict[str, Any]) -> bool:
    """Whether the package folder (or module file) ``path`` is on the import path of the cluster's daemon, which its
    workers share (the state's ``sys_path``): such a plug-in package needs no shipping to the workers."""
    parent = os.path.realpath(os.path.dirname(os.path.abspath(path)))
    return any(p and os.path.realpath(p) == parent for p in st.get("sys_path") or [])


def not_on_cluster_path(paths: list[str]) -> list[str]:
    """The plug-in package folders of ``paths`` that the running cluster's workers would not import by themselves
    (:func:`importable_by_cluster`): only those are shipped with an attached run's job (as ``py_modules``), so that
    a job with nothing to ship has no runtime environment and its actors can take the warm workers."""
    st = read_state() or {}
    return [p for p in paths if not importable_by_cluster(p, st)]


def await_fresh_workers(timeout_s: float = 5.0) -> bool:
    """When the running cluster keeps warm workers that imported other framework code than this driver has (an
    edit since they started), wait up to ``timeout_s`` seconds for the daemon to replace them (it looks every
    second). Returns True when the workers are current (or there are none)."""
    st = read_state() or {}
    if not st.get("warm_workers"):
        return True
    from aerodaas.clusters.warm_pool import code_fingerprint, package_roots  # lazy: a joined cluster only (every run imports this module, runtime.ray_start)

    if st.get("package_roots") not in (None, package_roots()):
        return True  # another install than this driver's: its workers run that one's code in any case
    fp = code_fingerprint()
    t_end = time.monotonic() + timeout_s
    while st.get("code_fingerprint") not in (None, fp):
        if time.monotonic() > t_end:
            return False
        time.sleep(0.1)
        st = read_state() or {}
    return True


def up(cpus: int = 3, timeout_s: float = 180.0, warm_workers: int = DEFAULT_WARM_WORKERS) -> dict[str, Any]:
    """Start the cluster (or return the running one's state with ``"already": True``) with ``cpus`` logical CPUs
    and ``warm_workers`` idle workers kept warm (0: none). Raises RuntimeError when the daemon exits or does not
    report ready within ``timeout_s`` seconds (its log path is named)."""
    st = read_state()
    if st:
        return {**st, "already": True}
    p = state_path()
    p.parent.mkdir(parents=True, exist_ok=True)
    logf = p.with_suffix(".log")
    with open(logf, "wb") as log:
        proc = subprocess.Popen([sys.executable, "-m", "aerodaas.clusters.persistent", "serve", str(int(cpus)),
                                 str(int(warm_workers))],
                                stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True, close_fds=True)
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        st = read_state()
        if st and st.get("pid") == proc.pid and "warm_driver" in st:  # the warm driver's start is the last
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
        import psutil  # lazy: psutil, only `aerodaas down` (every run imports this module)

        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except Exception:  # noqa: BLE001 - gone, or psutil missing
        return False


#: how often the daemon starts its head node when Ray's start times out (as aerodaas.runtime.ray_start does)
HEAD_START_ATTEMPTS = 3


def _start_head(cluster_type: Any, head_args: dict[str, Any]) -> Any:
    """``cluster_type(initialize_head=True, ...)`` (``ray.cluster_utils.Cluster``) with ``head_args``, started again
    (at most :data:`HEAD_START_ATTEMPTS` times) when Ray reports "timed out during startup": Ray gives a raylet a
    fixed 30 s to register with the GCS (``ray/_private/node.py``), which a loaded machine can miss. A failed
    attempt's processes (this daemon's descendants started by it: GCS, raylet, dashboard) are killed first, since
    the node object that would stop them was never made; each timed-out attempt first prints whether its raylet and
    GCS still ran and their logs' last lines (:mod:`aerodaas.clusters.node_logs`). Any other error, or the last
    timeout, is raised."""
    for attempt in range(HEAD_START_ATTEMPTS):
        before = set(reaper.descendants(os.getpid()))
        since_s = time.time()
        try:
            with agents_ahead():  # the raylet aborts when its agents take over 15 s (aerodaas.clusters.node_priority)
                return cluster_type(initialize_head=True, shutdown_at_exit=True, head_node_args=head_args)
        except Exception as e:  # noqa: BLE001 - Ray raises a bare Exception for this one
            if "timed out during startup" not in str(e):
                raise
            print(f"aerodaas up: Ray's node start timed out (attempt {attempt + 1} of {HEAD_START_ATTEMPTS})\n"
                  + failed_start_report(default_temp_dir(), os.getpid(), since_s, reaper.started_since(before)),
                  file=sys.stderr, flush=True)
            if attempt == HEAD_START_ATTEMPTS - 1:
                raise
            reaper.kill_started_since(before)
    raise AssertionError("unreachable")  # the loop returns or raises


def _serve(cpus: int, warm: int = DEFAULT_WARM_WORKERS) -> None:
    """The daemon: start the head node (with ``warm`` warm workers), write the state file, wait for SIGTERM/SIGINT,
    stop the node. Its imports stay in it: every run imports this module (:mod:`aerodaas.runtime.ray_start`), and
    only the daemon needs the node's (``# lazy: the cluster daemon only``)."""
    user_env = dict(os.environ)  # the warm driver's: the shell's, without what the node needs below
    from ray.cluster_utils import Cluster  # lazy: heavy ray, the cluster daemon only

    from aerodaas.clusters.local import enable_token_auth  # lazy: the cluster daemon only
    from aerodaas.clusters.loopback import loopback_only  # lazy: the cluster daemon only

    enable_token_auth()
    loopback_only()  # kept: this process exists only to run the node
    from aerodaas.clusters.worker_memory import lean_worker_imports, limit_malloc_arenas  # lazy: the cluster daemon only

    limit_malloc_arenas()  # the workers' C heap (aerodaas.clusters.worker_memory)
    lean_worker_imports()  # no pyarrow in the workers (aerodaas.clusters.worker_memory)
    lean_log_monitor()  # fewer listings of the logs folder when idle (aerodaas.clusters.log_monitor)
    system_config: dict[str, Any] = {"worker_niceness": 0}
    # the import path the node's workers share with this daemon: without sys.path[0], this module's own start
    # folder (`python -m` puts the caller's working directory there), which workers do not have
    worker_path = [p for p in sys.path[1:] if p]
    if warm > 0:
        from aerodaas.clusters.warm_pool import setup_hook_env  # lazy: the cluster daemon only

        # the raylet's workers inherit it: each imports the framework at start
        os.environ.update(setup_hook_env(state_path().parent / "warm_hook"))
        system_config["num_workers_soft_limit"] = max(cpus, warm)  # idle warm workers are not reaped
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    cluster = _start_head(Cluster, {
        "num_cpus": cpus, "labels": {"tier": "edge", "aerodaas/compute": "local"},
        "include_dashboard": True, "dashboard_host": "127.0.0.1", "_system_config": system_config,
        # None: 8265, or the next free port when another Ray on this machine holds it (as ray.init does); the
        # state file and `aerodaas up` give the one bound. Ray's RayParams default (8265 exactly, no retry) made
        # `aerodaas up` exit "Failed to bind to 127.0.0.1:8265" beside any other Ray with a dashboard
        "dashboard_port": None})
    node = cluster.head_node
    st = {"pid": os.getpid(), "address": cluster.address, "session_dir": node.get_session_dir_path(),
          "dashboard": getattr(node, "webui_url", None) or "", "started": time.time(), "warm_workers": 0,
          "sys_path": worker_path}
    lock = threading.Lock()

    def publish(fields: dict[str, Any]) -> None:
        with lock:
            if stop.is_set():  # the node is going down: the state file is removed, never written again
                return
            st.update(fields)
            tmp = state_path().with_suffix(".tmp")
            tmp.write_text(json.dumps(st))
            tmp.replace(state_path())

    if warm > 0:
        try:
            from aerodaas.clusters.warm_pool import READY_DIR, package_roots, raylet_pool, run_in_thread  # lazy: the cluster daemon only

            pool = raylet_pool(node, warm, publish, ready_dir=state_path().parent / "warm_hook" / READY_DIR)
            st.update(warm_workers=warm, package_roots=package_roots())
            run_in_thread(pool, stop)  # its first look publishes code_fingerprint
        except (ImportError, AttributeError, OSError, KeyError, IndexError) as e:  # this Ray lacks what it needs
            st.update(warm_workers=0, warm_error=f"{type(e).__name__}: {e}"[:300])
            print(f"aerodaas cluster: no warm workers ({st['warm_error']})", flush=True)
    from aerodaas.clusters import warm_driver_process  # lazy: the cluster daemon only

    driver = warm_driver_process.start(user_env, stop)
    st.update(warm_driver=warm_driver_process.status(driver))
    publish({})
    print(f"aerodaas cluster up: {st}", flush=True)
    try:
        stop.wait()
    finally:
        warm_driver_process.stop(driver)
        cluster.shutdown()
        try:
            if json.loads(state_path().read_text()).get("pid") == os.getpid():
                state_path().unlink()
        except (OSError, ValueError):
            pass
        print("aerodaas cluster down", flush=True)


if __name__ == "__main__" and len(sys.argv) >= 2 and sys.argv[1] == "serve":
    _serve(int(sys.argv[2]) if len(sys.argv) > 2 else 3,
           int(sys.argv[3]) if len(sys.argv) > 3 else DEFAULT_WARM_WORKERS)
