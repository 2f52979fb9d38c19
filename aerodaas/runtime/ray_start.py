"""Starting or joining Ray for a run's driver: a fresh loopback-only local Ray of our own, the persistent local
cluster of ``aerodaas up``, or the cluster of ``--address``; the background start that overlaps Ray's start with
other work; the temp directory of a local Ray (its Unix socket paths must fit ``AF_UNIX``'s limit).

Nothing here is called while an application is loaded (:mod:`aerodaas.runtime.app_loader`): only the runner
(:mod:`aerodaas.runtime.driver`) starts Ray.
"""
from __future__ import annotations

import contextlib
import logging
import os
import sys
import tempfile
import threading
import time

from aerodaas.clusters import reaper
from aerodaas.clusters.addresses import check_ray_address
from aerodaas.clusters.lean_head import without_monitor_and_api_server
from aerodaas.clusters.node_logs import failed_start_report
from aerodaas.clusters.node_priority import agents_ahead
from aerodaas.clusters.local import enable_token_auth
from aerodaas.clusters.log_monitor import lean_log_monitor
from aerodaas.clusters.loopback import loopback_only
from aerodaas.clusters.persistent import attached_address, await_fresh_workers, not_on_cluster_path
from aerodaas.clusters.ray_exports import light_collision_identifier
from aerodaas.clusters.worker_memory import addons_only_when_imported, lean_worker_imports, limit_malloc_arenas
from aerodaas.process.state import PROCESS, EarlyStart

__all__ = ["RayStartError", "RayAddressError", "init_ray", "ensure_ray", "start_ray_early", "shutdown_ray",
           "started_here", "ray_temp_dir", "SUN_PATH_MAX", "RAY_SOCKET_SUFFIX_MAX"]

#: the longest path an ``AF_UNIX`` socket may have on Linux: ``sizeof(sockaddr_un.sun_path)`` (108) minus its NUL
#: (unix(7))
SUN_PATH_MAX = 107
#: the longest tail Ray appends to its temp directory for a socket:
#: ``/session_YYYY-MM-DD_HH-MM-SS_ffffff_<pid up to 7 digits>/sockets/plasma_store`` (64 bytes; ray/_private/node.py
#: names the session and its ``sockets/`` files ``plasma_store`` and ``raylet``), with 8 bytes of margin
RAY_SOCKET_SUFFIX_MAX = 72


class RayStartError(RuntimeError):
    """Ray could not be started or reached (the message says which and why); ``aerodaas run`` exits 1 with it."""


class RayAddressError(RayStartError):
    """The Ray cluster of ``--address`` could not be reached (bad input: ``aerodaas run`` exits 2 naming it)."""


def started_here() -> bool:
    """True when this driver runs on a local Ray: its own, or the persistent cluster of ``aerodaas up`` (what this
    process did with Ray is :data:`aerodaas.process.state.PROCESS`'s ``ray``, process state, not run options)."""
    return PROCESS.ray.local or PROCESS.ray.attached_up


def ray_temp_dir(environ: dict[str, str] | None = None) -> str:
    """The temp directory for a local Ray of our own: Ray's own choice (``$RAY_TMPDIR``, else ``$TMPDIR``, else the
    system's, + ``/ray``; ray/_private/utils.py ``get_user_temp_dir``) when its socket paths (+
    :data:`RAY_SOCKET_SUFFIX_MAX` bytes) fit :data:`SUN_PATH_MAX`; else ``/tmp/aerodaas-ray-<uid>`` (a new
    ``/tmp/aerodaas-ray-*`` folder when that one belongs to another user): a Ray temp directory under a long home
    path made the raylet's socket path too long and the run unable to start. ``environ``: the environment to read
    (default ``os.environ``)."""
    env = os.environ if environ is None else environ
    base = env.get("RAY_TMPDIR") or env.get("TMPDIR") or tempfile.gettempdir()
    choice = os.path.join(base, "ray")
    if len(os.fsencode(choice)) + RAY_SOCKET_SUFFIX_MAX <= SUN_PATH_MAX:
        return choice
    short = f"/tmp/aerodaas-ray-{os.getuid()}"
    os.makedirs(short, mode=0o700, exist_ok=True)
    if os.stat(short).st_uid != os.getuid():
        return tempfile.mkdtemp(prefix=f"aerodaas-ray-{os.getuid()}-", dir="/tmp")
    return short


def _up_address() -> str | None:
    """The address of a running `aerodaas up` cluster, unless ``AERODAAS_NO_ATTACH=1``."""
    if os.environ.get("AERODAAS_NO_ATTACH") == "1":
        return None

    return attached_address()


def _shipped_plugins(address: str | None, up_address: str | None) -> dict:
    """``ray.init``'s runtime_env keyword: installed plug-in packages (entry points) travel to a cluster we join or
    attach to (its nodes may not have them; ``AERODAAS_SHIP_PLUGINS=0``: not)."""
    from aerodaas.plugins.registry import plugin_package_paths  # lazy: heavy pydantic

    ship = plugin_package_paths() if (address or up_address) and os.environ.get("AERODAAS_SHIP_PLUGINS") != "0" \
        else []
    if up_address:  # not what `aerodaas up`'s workers import already: their warm pool serves jobs without one

        ship = not_on_cluster_path(ship)
    return {"runtime_env": {"py_modules": ship}} if ship else {}


def _attach_up(up_address: str, renv: dict) -> None:
    """Join the persistent local cluster of `aerodaas up` (:mod:`aerodaas.clusters.persistent`): loopback, token
    auth, like our own."""
    import ray  # lazy: heavy ray

    enable_token_auth()  # the cluster was started with token auth: the driver must present the token
    if not await_fresh_workers():
        print("aerodaas: warning: the local cluster's warm workers still hold framework code older than this "
              "driver's; `aerodaas down && aerodaas up` restarts them", file=sys.stderr, flush=True)
    restore = loopback_only()
    try:
        ray.init(address=up_address, log_to_driver=True, configure_logging=True, logging_level="warning", **renv)
    finally:
        restore()
    PROCESS.ray.attached_up = True
    print(f"aerodaas: attached to the local cluster of `aerodaas up` at {up_address} (`aerodaas down` stops it)",
          file=sys.stderr, flush=True)


def _start_local(dashboard: bool) -> None:
    """A fresh loopback-only local Ray of our own (never one that `ray start` left on this machine), retried up to
    3 times when Ray's startup times out on a loaded machine (each timed-out attempt prints whether its raylet and
    GCS still ran and their logs' last lines: :mod:`aerodaas.clusters.node_logs`), and once without the dashboard
    when that fails.
    Without ``dashboard`` its head starts neither the autoscaler monitor nor the dashboard's API server
    (:mod:`aerodaas.clusters.lean_head`).

    num_cpus=3: the run's actors reserve no CPU (num_cpus=0), so the CPU resource only sizes Ray's pool of workers
    prestarted while the app is built: three, which the recorder, a drone and an analytics actor take (1.4 s
    instead of 2.0 s from Ray ready to the actors ready, `aerodaas bench startup`)."""
    import ray  # lazy: heavy ray

    limit_malloc_arenas()  # the workers' C heap: see the module
    lean_worker_imports()  # no pyarrow in the workers (aerodaas.clusters.worker_memory)
    lean_log_monitor()  # fewer listings of the logs folder when idle (aerodaas.clusters.log_monitor)
    # Ray's processes end with this driver, however it ends (see the module); kept: the process's own
    PROCESS.ray.reaper = reaper.ensure_started() or PROCESS.ray.reaper
    temp_dir = ray_temp_dir()
    for attempt in range(3):
        restore = loopback_only()
        before = set(reaper.descendants(os.getpid()))
        since_s = time.time()
        try:
            # the dashboard (loopback only) serves `ray list actors` and the actor view of the run
            # worker_niceness 0: drone actors fly the vehicles; Ray's default niceness 15 would let any other
            # process on the machine (a SITL autopilot, a compiler) starve their control loops.
            # Without the dashboard, no autoscaler monitor and no API server: they serve such a run nothing and
            # lie on the path to the first frame (aerodaas.clusters.lean_head)
            # the node's agents start ahead of the machine's load: the raylet aborts when they take over 15 s to
            # write their ports (aerodaas.clusters.node_priority)
            with (contextlib.nullcontext() if dashboard else without_monitor_and_api_server()), agents_ahead():
                ray.init(address="local", labels={"tier": "edge"}, include_dashboard=dashboard,
                         dashboard_host="127.0.0.1", log_to_driver=True, _system_config={"worker_niceness": 0},
                         num_cpus=3, configure_logging=True, logging_level="warning", _temp_dir=temp_dir)
            restore()
            break
        except Exception as e:  # noqa: BLE001 - Ray raises a bare Exception for this one
            restore()
            # Ray gives its raylet a fixed 30 s to register with the GCS (ray/_private/node.py); a heavily loaded
            # machine can miss that: start again (at most 3 times) rather than fail the run. A dashboard that fails
            # to start is not worth failing the run for: start again without it
            timed_out = "timed out during startup" in str(e)
            if timed_out:  # whether the raylet died or was slow, from what the attempt left (before it is killed)
                print(f"aerodaas: warning: Ray's node start timed out (attempt {attempt + 1} of 3)\n"
                      + failed_start_report(temp_dir, os.getpid(), since_s, reaper.started_since(before)),
                      file=sys.stderr, flush=True)
            ray.shutdown()
            # the failed attempt's GCS, raylet, dashboard: ray.shutdown() does not stop a node that never started
            reaper.kill_started_since(before, temp_dir)
            if dashboard and "dashboard" in str(e).lower() and attempt < 2:
                print(f"aerodaas: warning: Ray's dashboard did not start ({str(e).splitlines()[0][:120]}); "
                      f"running without it", file=sys.stderr, flush=True)
                dashboard = False
                continue
            if not timed_out or attempt == 2:
                raise
    PROCESS.ray.local = True


def init_ray(address: str | None, dashboard: bool = False) -> None:
    """Start or join Ray for this driver: join the cluster at ``address`` (``ray://`` or ``host:port``; checked to
    be a gRPC server first, :func:`aerodaas.clusters.addresses.check_ray_address`, so a port that is no Ray GCS
    fails within 10 s instead of hanging); else attach to the persistent local cluster of ``aerodaas up`` if one
    runs; else start a fresh loopback-only local Ray of our own (``dashboard``: with Ray's dashboard on
    127.0.0.1). Raises ValueError for a bad ``address``, else what ``ray.init`` raises."""
    import ray  # lazy: heavy ray

    # the driver's first actor creation builds Ray's serialisation context, which imports pyarrow, Pydantic's v1
    # package and Starlette for Ray's reducers: not for a run that uses none of them (aerodaas.clusters.worker_memory)
    addons_only_when_imported()
    light_collision_identifier()  # the actor classes' export: no disassembly (aerodaas.clusters.ray_exports)
    up_address = None if address else _up_address()
    renv = _shipped_plugins(address, up_address)
    if address:
        check_ray_address(address, timeout_s=10.0)
        ray.init(address=address, log_to_driver=True, include_dashboard=False, **renv)
    elif up_address:
        _attach_up(up_address, renv)
    else:
        _start_local(dashboard)


def start_ray_early(address: str | None = None, dashboard: bool = False) -> None:
    """Start (or connect to) Ray in a background thread; the next :func:`ensure_ray` waits for it (an optimisation
    of the runner: Ray's start overlaps other work). Ray's processes are tied to the thread that started them
    (``PR_SET_PDEATHSIG``), so that thread stays alive, idle, for the life of the driver. Started outside the main
    thread, ``ray.init`` leaves the main thread's SIGTERM handler alone (in the main thread it installs its own,
    which exits at once: ``aerodaas run`` then died with SIGABRT instead of stopping the mission cleanly). Nothing
    to do when Ray is already initialized."""
    import ray  # lazy: heavy ray

    if PROCESS.ray.early is not None or ray.is_initialized():
        return
    early = PROCESS.ray.early = EarlyStart(address)

    def keeper() -> None:
        class _NoSigtermNotice(logging.Filter):  # the CLI installs its own SIGTERM handler in the main thread
            def filter(self, record: logging.LogRecord) -> bool:
                return not str(record.msg).startswith("SIGTERM handler is not set")

        logging.getLogger("ray._private.worker").addFilter(_NoSigtermNotice())
        try:
            init_ray(address, dashboard)
        except BaseException as e:  # surfaced by ensure_ray in the main thread
            early.error = e
        early.ready.set()
        threading.Event().wait()

    threading.Thread(target=keeper, name="aerodaas-ray-keeper", daemon=True).start()


def ensure_ray(address: str | None = None, dashboard: bool = False) -> bool:
    """Connect to (``address``) or start a local Ray (``dashboard``: with its dashboard); returns True when the
    cluster has ``tier=cloud`` nodes. Raises :class:`RayAddressError` (``address`` unreachable or no Ray cluster) or
    :class:`RayStartError`."""
    import ray  # lazy: heavy ray

    where = f"the Ray cluster at {address!r}" if address else "a local Ray"
    err_cls = RayAddressError if address else RayStartError
    early = PROCESS.ray.early
    if early is not None and early.address == address:
        early.ready.wait()
        if early.error is not None:
            err, PROCESS.ray.early = early.error, None
            if isinstance(err, KeyboardInterrupt):
                raise err
            raise err_cls(f"could not start {where}: {type(err).__name__}: {err}") from err
    if not ray.is_initialized():
        try:
            init_ray(address, dashboard)
        except Exception as e:  # noqa: BLE001 - Ray raises bare Exceptions (node start time-outs, ...)
            raise err_cls(f"could not start {where}: {type(e).__name__}: {e}") from e
    return any(n.get("Labels", {}).get("tier") == "cloud" for n in ray.nodes() if n.get("Alive"))


def shutdown_ray() -> None:
    """Shut down the Ray this driver started (a joined or attached cluster is only disconnected from when this
    process ends). Imports nothing when Ray never started (a run refused for its input ends faster)."""
    if PROCESS.ray.early is None and "ray" not in sys.modules:
        return  # Ray was never imported, so never started by this process
    import ray  # lazy: heavy ray

    if PROCESS.ray.early is not None:
        PROCESS.ray.early.ready.wait()
    if PROCESS.ray.local and ray.is_initialized():
        ray.shutdown()
    PROCESS.ray.local = False
    PROCESS.ray.early = None
