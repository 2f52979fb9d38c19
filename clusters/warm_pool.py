"""Warm workers for the persistent local cluster of ``aerodaas up`` (a run attached to it reaches
its first processed frame in about a second).

Ray's worker processes are started per job: every ``aerodaas run`` is a new job (driver), so without help each of its
actors waits for a fresh Python process that starts Ray's core worker and imports the framework (0.5 s or more of CPU
each, on a 2-core machine the largest part of an attached start). Two things remove that wait:

- **Workers started ahead, for no job.** The daemon of ``aerodaas up`` asks its raylet for idle Python workers
  through the raylet's own ``NodeManagerService.PrestartWorkers`` call (``src/ray/protobuf/node_manager.proto``: no
  ``job_id``, no runtime environment, a keep-alive), the call Ray's core worker uses for the same purpose. Such a
  worker is bound to the first job that needs one, so the next run's actors are placed in processes that already run.
  Only jobs without a runtime environment of their own can use them (Ray matches workers by the job's runtime
  environment hash); that is why an attached run ships no plug-in packages that the cluster's interpreter already
  imports (:func:`aerodaas.runtime.ray_start.init_ray`).
- **The framework imported ahead.** The daemon sets Ray's worker setup hook (``worker_process_setup_hook``, here
  through the environment variable Ray's ``default_worker.py`` reads at start, inherited from the raylet) to a
  generated module (:func:`setup_hook_env`) that calls :func:`preimport`, which imports the modules the drone,
  analytics and recorder actors use. Neither raises: a module that fails to import is left to the actor that needs
  it, which then reports the error as before.

A warm worker holds the framework's code as it was when the worker started. :func:`code_fingerprint` (the relative
path, size and modification time of every module file of ``aerodaas``) is checked every second; once a change has
settled for ``settle_s``, every warm worker started before it is stopped (SIGTERM) and replaced, and only then does
the state file carry the new fingerprint, so that a run started in between waits for the refresh
(:func:`aerodaas.clusters.persistent.await_fresh_workers`). :class:`WarmPool` documents the rest (refill delay, the
pause when workers do not stay up).

Refills wait ``settle_s`` (2 s) after a run took workers, so that starting new workers does not compete with that
run's own start on a small machine. Idle workers cost memory (``docs/clusters.md`` gives the measured PSS).
"""
from __future__ import annotations

import gc
import hashlib
import importlib
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import psutil

__all__ = ["HOOK_MODULE", "PREIMPORT_MODULES", "READY_DIR", "WarmPool", "code_fingerprint", "forget_ended",
           "hook_done", "package_roots", "preimport", "raylet_pool", "run_in_thread", "setup_hook_env"]

#: the process title Ray gives an idle Python worker (exactly: not ``ray::IDLE_SPILL_WORKER`` / ``_RESTORE_WORKER``)
IDLE_TITLE = "ray::IDLE"

#: what the drone, analytics and recorder actors import at construction and set-up (measured from the modules loaded
#: in each actor's worker during ``apps/vehicle_tracking.py``); their own imports bring the rest (numpy, OpenCV,
#: pydantic, shapely, scipy, mcap)
PREIMPORT_MODULES = (
    "aerodaas.actors.host.drone_actor", "aerodaas.actors.host.analytics_actor", "aerodaas.actors.recording.actor",
    "aerodaas.actors.host.assembly", "aerodaas.actors.drone.component", "aerodaas.actors.analytics.component",
    "aerodaas.actors.drone.scheduler_component", "aerodaas.actors.sensors.camera", "aerodaas.actors.recording.recorder",
    "aerodaas.backends.sim", "aerodaas.sim.world", "aerodaas.perception.detect", "aerodaas.perception.tracking",
    "aerodaas.recording.writer", "onnxruntime",
    # the follow analytics' track assignment (aerodaas.perception.tracking, on its first frame with tracks): 0.3 s
    "scipy.optimize",
    # the built-in analytics (detector, follow, monitoring) that an actor's spec unpickles, and the detector's
    # set-up (its options and decoders)
    "aerodaas.analytics.core", "aerodaas.perception.options",
)

#: the environment variable Ray's ``default_worker.py`` reads for a module-path setup hook
#: (``ray._private.ray_constants.WORKER_PROCESS_SETUP_HOOK_ENV_VAR``)
_HOOK_ENV_FALLBACK = "__RAY_WORKER_PROCESS_SETUP_HOOK_ENV_VAR"


def preimport() -> None:
    """Ray worker setup hook: first what the node's own hook would have done
    (:func:`aerodaas.clusters.worker_memory.worker_setup`: Ray's serialisation add-ons register only for libraries
    the worker imported; this hook takes that one's place in the environment, and without it each warm worker
    imported pyarrow, Pydantic's v1 package and Starlette when its first actor of a run deserialised its first
    argument, on the way to the run's first frame), then import :data:`PREIMPORT_MODULES`, then move everything
    they allocated out of the cyclic garbage collector's sight (``gc.collect()`` then ``gc.freeze()``, the pattern
    CPython documents for pre-fork servers): an actor's set-up collects once before its run
    (``DataPlane.watch_gc``), which then scans only what the actor itself made — 0.06 s of CPU less per actor on the
    2-core machine kind — and so does every full collection during the run. Never raises (a failed import is
    skipped)."""
    try:
        from aerodaas.clusters.worker_memory import worker_setup  # lazy: a Ray worker's start only

        worker_setup()
    except BaseException:  # noqa: BLE001 - a warm-up must never stop a worker from starting
        pass
    for name in PREIMPORT_MODULES:
        try:
            importlib.import_module(name)
        except BaseException:  # noqa: BLE001 - a warm-up must never stop a worker from starting
            pass
    gc.collect()
    gc.freeze()


#: the folder beside the hook module where each worker leaves an empty file named by its pid once its hook has run
READY_DIR = "ready"
#: the setup hook's own module, written by :func:`setup_hook_env`: loading it imports nothing, so that a framework
#: that does not import (an edit in progress) cannot stop a worker from starting (Ray ends a worker whose hook
#: fails to load, Ray's spill workers included)
HOOK_MODULE = "aerodaas_warm_hook"
_HOOK_SOURCE = (
    '"""Written by `aerodaas up` (aerodaas.clusters.warm_pool): Ray\'s worker setup hook of its node."""\n\n\n'
    "def preimport():\n"
    "    try:\n"
    "        from aerodaas.clusters.warm_pool import preimport as warm\n"
    "        warm()\n"
    "    except BaseException:  # a warm-up never stops a worker from starting\n"
    "        pass\n"
    "    try:  # done: the worker is warm (Ray titles it ray::IDLE before its hook runs, not after)\n"
    "        import os\n"
    f"        ready = os.path.join(os.path.dirname(os.path.abspath(__file__)), {READY_DIR!r})\n"
    "        os.makedirs(ready, exist_ok=True)\n"
    "        open(os.path.join(ready, str(os.getpid())), 'w').close()\n"
    "    except BaseException:\n"
    "        pass\n")


def setup_hook_env(hook_dir: str | os.PathLike) -> dict[str, str]:
    """Write the hook module into ``hook_dir`` (and empty its :data:`READY_DIR`) and return the environment entries (Ray's setup-hook variable, and
    ``PYTHONPATH`` with ``hook_dir`` first) that make every worker of a node started with them run
    :func:`preimport` at start. Raises OSError if the module cannot be written."""
    try:
        from ray._private import ray_constants  # lazy: heavy ray

        key = getattr(ray_constants, "WORKER_PROCESS_SETUP_HOOK_ENV_VAR", _HOOK_ENV_FALLBACK)
    except ImportError:
        key = _HOOK_ENV_FALLBACK
    os.makedirs(hook_dir, exist_ok=True)
    ready = os.path.join(hook_dir, READY_DIR)
    if os.path.isdir(ready):  # an earlier daemon's workers
        for name in os.listdir(ready):
            try:
                os.remove(os.path.join(ready, name))
            except OSError:
                pass
    path = os.path.join(hook_dir, f"{HOOK_MODULE}.py")
    with open(path, "w") as f:
        f.write(_HOOK_SOURCE)
    pp = os.environ.get("PYTHONPATH")
    return {key: f"{HOOK_MODULE}.preimport", "PYTHONPATH": os.pathsep.join([str(hook_dir)] + ([pp] if pp else []))}


def package_roots() -> list[str]:
    """The folders of the installed ``aerodaas`` package and of its sub-packages installed from the repository's
    top level (``actors``, ``schedulers``, ``clusters``)."""
    spec = importlib.util.find_spec("aerodaas")  # the package's folder, without importing its public API
    roots = list(spec.submodule_search_locations or []) if spec is not None else []
    for sub in ("actors", "schedulers", "clusters"):  # installed as aerodaas.<sub> from the repository's top level
        try:
            mod = importlib.import_module(f"aerodaas.{sub}")
        except ImportError:
            continue
        roots += [p for p in getattr(mod, "__path__", []) if not any(p.startswith(r + os.sep) for r in roots)]
    return roots


def code_fingerprint(roots: list[str] | None = None) -> str:
    """A digest of every ``*.py`` file under ``roots`` (default: :func:`package_roots`): its path within its root,
    size and modification time (ns). Changes when any module file is edited, added or removed. Unreadable folders
    are skipped; never raises."""
    h = hashlib.blake2b(digest_size=12)
    for root in sorted(roots if roots is not None else package_roots()):
        stack = [root]
        while stack:
            d = stack.pop()
            try:
                entries = sorted(os.scandir(d), key=lambda e: e.name)
            except OSError:
                continue
            for e in entries:
                try:
                    if e.is_dir(follow_symlinks=False):
                        if e.name != "__pycache__":
                            stack.append(e.path)
                    elif e.name.endswith(".py"):
                        st = e.stat()
                        rel = os.path.relpath(e.path, root)
                        h.update(f"{os.path.basename(root)}/{rel}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())
                except OSError:
                    continue
    return h.hexdigest()


@dataclass
class WarmPool:
    """Keeps ``size`` idle Python workers on one raylet (see the module).

    ``idle_pids()`` lists the raylet's idle workers, ``starting_pids()`` the workers being started (counted towards
    the pool, never stopped while starting), ``prestart(n)`` asks the raylet for ``n`` more (it starts at most as many
    as the node has CPUs per call), ``stop_pids(pids)`` ends idle ones and returns once they are gone,
    ``started_at(pid)`` is a worker's start (epoch seconds), ``alive(pid)`` whether it still exists,
    ``fingerprint()`` is :func:`code_fingerprint`, ``publish(fields)`` reports the pool's state (the daemon writes it
    to its state file), ``wall()`` is the epoch clock. Call :meth:`step` about once a second from one thread."""

    size: int
    idle_pids: Callable[[], list[int]]
    prestart: Callable[[int], None]
    stop_pids: Callable[[list[int]], None]
    starting_pids: Callable[[], list[int]] = list
    started_at: Callable[[int], float] = lambda pid: 0.0
    alive: Callable[[int], bool] = lambda pid: True
    fingerprint: Callable[[], str] = code_fingerprint
    publish: Callable[[dict], None] = lambda fields: None
    wall: Callable[[], float] = time.time
    #: seconds a run's take of workers, or an edit of the framework, must have settled before the pool acts
    settle_s: float = 2.0
    #: ``size`` workers that ended while starting (never idle, never taken by a job) within ``crash_window_s``: they
    #: do not stay up (e.g. the framework no longer imports); the pool pauses for ``crash_pause_s`` and says so
    crash_window_s: float = 60.0
    crash_pause_s: float = 30.0
    short_since: float | None = None
    last_fingerprint: str = ""  # of the code the warm workers hold (published)
    pending: tuple[str, float, float] | None = None  # (new fingerprint, since, since on the wall clock): settling
    stale: tuple[str, float] | None = None  # (new fingerprint, wall time of the edit): older workers to replace
    seen_starting: set = field(default_factory=set)
    failed: list[float] = field(default_factory=list)  # when workers ended while starting
    paused_until: float = -1.0
    last_published: dict = field(default_factory=dict)
    errors: int = 0

    def step(self, now: float) -> None:
        """One look at the pool (see the class): replace workers older than a settled edit of the framework, then
        publish its new fingerprint; refill once the pool has been short for ``settle_s`` (at once when it was never
        filled or after an edit); pause when workers do not stay up; publish ``warm_idle`` (idle workers now),
        ``code_fingerprint`` (of the code they hold) and ``warm_error`` (None when healthy). A failed call is
        counted in ``errors`` and published as ``warm_error``; never raises."""
        try:
            fp = self.fingerprint()
            idle, starting = self.idle_pids(), self.starting_pids()
            self._count_failures(now, idle, starting)
            at_once = not self.last_fingerprint  # never filled yet
            if at_once:
                self.last_fingerprint = fp
            elif fp != (self.stale[0] if self.stale else self.last_fingerprint):
                if self.pending is None or self.pending[0] != fp:
                    self.pending = (fp, now, self.wall())  # an edit (a checkout touches many files): let it settle
                elif now - self.pending[1] >= self.settle_s:
                    self.stale, self.pending = (fp, self.pending[2]), None
            else:
                self.pending = None
            if self.stale is not None:  # workers started before the edit hold the old code: replace them
                old = [p for p in idle if self.started_at(p) < self.stale[1]]
                if old:
                    self.stop_pids(old)  # returns once they are gone
                    idle, at_once = [p for p in idle if p not in old], True
                if not any(self.started_at(p) < self.stale[1] for p in starting):
                    self.last_fingerprint, self.stale = self.stale[0], None  # every warm worker is fresh now
            missing = self.size - len(idle) - len(starting)
            self.failed = [t for t in self.failed if now - t < self.crash_window_s]
            if missing <= 0:
                self.short_since = None
            elif now < self.paused_until:
                pass
            elif len(self.failed) >= self.size:
                self.paused_until, self.failed = now + self.crash_pause_s, []
                self._publish({"warm_error": f"{self.size} workers ended while starting within "
                                             f"{self.crash_window_s:g} s; pausing {self.crash_pause_s:g} s (does the "
                                             "framework import?)"})
            elif at_once or (self.short_since is not None and now - self.short_since >= self.settle_s):
                self.prestart(missing)
                self.short_since = None
            elif self.short_since is None:
                self.short_since = now
            fields: dict = {"warm_idle": len(idle), "code_fingerprint": self.last_fingerprint}
            if len(idle) >= self.size:
                fields["warm_error"] = None  # healthy again
            self._publish(fields)
        except Exception as e:  # noqa: BLE001 - the pool is an optimisation: the cluster keeps running without it
            self.errors += 1
            self._publish({"warm_error": f"{type(e).__name__}: {e}"[:300]})

    def _count_failures(self, now: float, idle: list[int], starting: list[int]) -> None:
        """Workers seen starting that are now neither idle, starting nor alive ended while starting (a job that
        took one keeps it alive under another title)."""
        for pid in self.seen_starting - set(idle) - set(starting):
            if not self.alive(pid):
                self.failed.append(now)
        self.seen_starting = set(starting)

    def _publish(self, fields: dict) -> None:
        if any(self.last_published.get(k, "unset") != v for k, v in fields.items()):
            self.last_published.update(fields)
            self.publish(dict(fields))


def hook_done(ready_dir: str | os.PathLike | None, pid: int, started_at: float) -> bool:
    """Whether the worker ``pid`` (started at ``started_at``, epoch seconds) has run the setup hook: its file in
    ``ready_dir`` (the hook folder's :data:`READY_DIR`) exists and was written after the worker started (not by an
    earlier process with the same pid). ``ready_dir`` None: no hook, every worker counts as done."""
    if ready_dir is None:
        return True
    try:
        return os.stat(os.path.join(ready_dir, str(pid))).st_mtime >= started_at - 1.0  # the stat clock's grain
    except OSError:
        return False


def forget_ended(ready_dir: str | os.PathLike | None, alive: set[int]) -> None:
    """Remove the ready files of workers no longer in ``alive`` (pids). Never raises."""
    if ready_dir is None:
        return
    try:
        names = os.listdir(ready_dir)
    except OSError:
        return
    for name in names:
        if name.isdigit() and int(name) not in alive:
            try:
                os.remove(os.path.join(ready_dir, name))
            except OSError:
                pass


def raylet_pool(node, size: int, publish: Callable[[dict], None],
                ready_dir: str | os.PathLike | None = None) -> WarmPool:
    """A :class:`WarmPool` on the raylet of ``node`` (a ``ray._private.node.Node`` this process started), using its
    ``PrestartWorkers`` gRPC call with the cluster's token. ``ready_dir``: the hook folder's :data:`READY_DIR`; a
    worker Ray titles ``ray::IDLE`` counts as idle only once its hook has run (:func:`hook_done`; Ray sets the
    title when the worker connects, before the hook imports the framework), as starting until then. Raises
    ImportError/AttributeError when this Ray lacks what it needs (the daemon then runs without a pool)."""
    from ray._private import ray_constants  # lazy: heavy ray
    from ray._private.grpc_utils import init_grpc_channel  # lazy: heavy ray
    from ray.core.generated import common_pb2, node_manager_pb2, node_manager_pb2_grpc  # lazy: heavy ray

    raylet = psutil.Process(node.all_processes[ray_constants.PROCESS_TYPE_RAYLET][0].process.pid)
    stub = node_manager_pb2_grpc.NodeManagerServiceStub(init_grpc_channel(f"127.0.0.1:{node.node_manager_port}"))

    def workers(title_idle: bool) -> list[int]:
        out, children = [], raylet.children()
        for p in children:
            try:
                cmd = p.cmdline()
                if cmd and cmd[0] == IDLE_TITLE:
                    warm = hook_done(ready_dir, p.pid, p.create_time())
                    if warm == title_idle:  # idle with its hook run; starting while the hook imports
                        out.append(p.pid)
                elif cmd and not title_idle and any(c.endswith("default_worker.py") for c in cmd[:3]) \
                        and not any(c.startswith("--worker-type=") and not c.endswith("=WORKER") for c in cmd):
                    out.append(p.pid)  # a Python worker still starting (not yet connected)
            except psutil.Error:
                continue
        if title_idle:
            forget_ended(ready_dir, {p.pid for p in children})
        return out

    def prestart(n: int) -> None:
        req = node_manager_pb2.PrestartWorkersRequest(language=common_pb2.PYTHON, num_workers=int(n),
                                                      keep_alive_duration_secs=24 * 3600)
        stub.PrestartWorkers(req, timeout=10)

    def stop_pids(pids: list[int]) -> None:
        procs = []
        for pid in pids:
            try:
                p = psutil.Process(pid)
                if p.cmdline()[:1] == [IDLE_TITLE]:  # still idle right now: never a worker that took a task
                    p.terminate()
                    procs.append(p)
            except (psutil.Error, IndexError):
                continue
        psutil.wait_procs(procs, timeout=10)

    def started_at(pid: int) -> float:
        try:
            return psutil.Process(pid).create_time()
        except psutil.Error:
            return 0.0

    return WarmPool(size=size, idle_pids=lambda: workers(True), starting_pids=lambda: workers(False),
                    prestart=prestart, stop_pids=stop_pids, started_at=started_at, alive=psutil.pid_exists,
                    publish=publish)


def run_in_thread(pool: WarmPool, stop: threading.Event, period_s: float = 1.0) -> threading.Thread:
    """Call ``pool.step`` every ``period_s`` seconds until ``stop`` is set (a daemon thread, returned started)."""

    def loop() -> None:
        while not stop.is_set():
            pool.step(time.monotonic())
            stop.wait(period_s)

    t = threading.Thread(target=loop, name="aerodaas-warm-pool", daemon=True)
    t.start()
    return t
