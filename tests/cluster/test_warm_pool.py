"""The warm-worker pool of ``aerodaas up`` (aerodaas.clusters.warm_pool) without Ray: when it refills, when it throws
warm workers away (the framework's code changed), what it reports; the code fingerprint; the setup hook. The pool
on a real cluster, used by a real run, is tested in test_example_plugins (cluster group)."""
from __future__ import annotations

import os

from aerodaas.clusters import warm_pool
from aerodaas.clusters.persistent import importable_by_cluster
from aerodaas.clusters.warm_pool import WarmPool, code_fingerprint


class FakeRaylet:
    """Workers start idle at once (or, with ``start_fails``, start and die); ``clock`` is the wall clock."""

    def __init__(self, start_fails: bool = False) -> None:
        self.idle: list[int] = []
        self.starting: list[int] = []
        self.born: dict[int, float] = {}
        self.dead: set[int] = set()
        self.next_pid = 100
        self.stopped: list[int] = []
        self.prestarts: list[int] = []
        self.fp = "a"
        self.clock = 0.0
        self.start_fails = start_fails
        self.published: list[dict] = []

    def prestart(self, n: int) -> None:
        self.prestarts.append(n)
        for _ in range(min(n, 2)):  # the raylet starts at most its CPUs' worth per call (here 2)
            self.born[self.next_pid] = self.clock
            (self.starting if self.start_fails else self.idle).append(self.next_pid)
            self.next_pid += 1

    def stop(self, pids: list[int]) -> None:
        for pid in pids:
            self.stopped.append(pid)
            self.idle.remove(pid)
            self.dead.add(pid)

    def pool(self, size: int = 3) -> WarmPool:
        return WarmPool(size=size, idle_pids=lambda: list(self.idle), starting_pids=lambda: list(self.starting),
                        prestart=self.prestart, stop_pids=self.stop, started_at=lambda pid: self.born[pid],
                        alive=lambda pid: pid not in self.dead, fingerprint=lambda: self.fp,
                        publish=self.published.append, wall=lambda: self.clock, settle_s=2.0)

    def step(self, pool: WarmPool, now: float) -> None:
        self.clock = now
        pool.step(now)


def test_the_pool_fills_at_once_then_refills_only_after_a_run_has_settled():
    r = FakeRaylet()
    pool = r.pool(size=3)
    pool.step(0.0)
    assert r.prestarts == [3] and len(r.idle) == 2  # first fill at once; the raylet started 2 (its CPUs)
    pool.step(1.0)  # still one short: waits settle_s before asking again
    assert r.prestarts == [3]
    pool.step(3.1)
    assert r.prestarts == [3, 1] and len(r.idle) == 3
    pool.step(4.0)
    assert r.prestarts == [3, 1]  # full: nothing asked
    taken = r.idle[:2]
    r.idle = r.idle[2:]  # a run's actors took two warm workers
    pool.step(5.0)
    pool.step(6.0)
    assert r.prestarts == [3, 1], "refilled while the run was still starting"
    pool.step(7.1)
    assert r.prestarts == [3, 1, 2] and not set(taken) & set(r.idle) and len(r.idle) == 3
    assert r.published[-1]["warm_idle"] == 1 and r.published[-1]["code_fingerprint"] == "a"


def test_a_settled_code_change_replaces_every_older_warm_worker_before_it_is_published():
    r = FakeRaylet()
    pool = r.pool(size=2)
    r.step(pool, 0.0)
    old = list(r.idle)
    assert len(old) == 2
    r.fp = "b"  # a module file of the framework was edited ...
    r.step(pool, 1.0)
    r.fp = "c"  # ... and another (a checkout touches many files): nothing happens until the code settles
    r.step(pool, 2.0)
    r.step(pool, 3.0)
    assert r.stopped == [] and r.published[-1]["code_fingerprint"] == "a"  # the workers still hold "a"
    r.starting.append(999)  # a worker that began starting before the edit settled (it holds old code) ...
    r.born[999] = 1.5
    r.step(pool, 4.0)
    assert r.stopped == old and r.prestarts == [2, 1] and not set(old) & set(r.idle)
    assert r.published[-1]["code_fingerprint"] == "a", "published while an old worker was still starting"
    r.starting.remove(999)  # ... becomes idle: it is replaced too, then the new code is published
    r.idle.append(999)
    r.step(pool, 5.0)
    assert 999 in r.stopped and 999 not in r.idle
    assert r.published[-1]["code_fingerprint"] == "c"


def test_workers_that_end_while_starting_pause_the_pool_and_healthy_ones_clear_it():
    r = FakeRaylet(start_fails=True)
    pool = r.pool(size=2)
    t = 0.0
    while not pool.last_published.get("warm_error") and t < 60:
        seen = list(r.starting)
        r.step(pool, t)
        for pid in seen:  # each start fails: a worker seen starting exits before it is ever idle
            r.starting.remove(pid)
            r.dead.add(pid)
        t += 1.0
    assert "ended while starting" in pool.last_published["warm_error"]
    asked = sum(r.prestarts)
    r.step(pool, t + 20.0)
    assert sum(r.prestarts) == asked  # paused for crash_pause_s
    r.start_fails = False  # fixed: workers stay up again, the pool fills and the error is cleared
    for k in range(6):
        r.step(pool, t + 31.0 + 2.1 * k)
    assert len(r.idle) == 2 and pool.last_published["warm_error"] is None


def test_a_run_taking_workers_is_no_failure():
    r = FakeRaylet()
    pool = r.pool(size=2)
    r.step(pool, 0.0)
    for k in range(30):  # a run takes both warm workers every 3 s (they live on as its actors)
        r.idle.clear()
        r.step(pool, 1.0 + 3 * k)
        r.step(pool, 3.1 + 3 * k)
    assert not pool.failed and "warm_error" not in [k for p in r.published for k, v in p.items() if v]


def test_a_failing_raylet_call_is_reported_and_never_raises():
    r = FakeRaylet()

    def broken(n: int) -> None:
        raise ConnectionError("raylet gone")

    pool = WarmPool(size=2, idle_pids=list, prestart=broken, stop_pids=r.stop, fingerprint=lambda: "a",
                    publish=r.published.append)
    pool.step(0.0)
    assert pool.errors == 1 and r.published[-1] == {"warm_error": "ConnectionError: raylet gone"}


def test_the_code_fingerprint_follows_module_files_only(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__pycache__").mkdir()
    (pkg / "a.py").write_text("x = 1\n")
    (pkg / "sub" / "b.py").write_text("y = 2\n")
    first = code_fingerprint([str(pkg)])
    assert code_fingerprint([str(pkg)]) == first
    (pkg / "__pycache__" / "a.cpython-311.pyc").write_bytes(b"\0")
    (pkg / "notes.txt").write_text("not code")
    assert code_fingerprint([str(pkg)]) == first
    st = (pkg / "sub" / "b.py").stat()
    os.utime(pkg / "sub" / "b.py", ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    edited = code_fingerprint([str(pkg)])
    assert edited != first
    (pkg / "c.py").write_text("")
    assert code_fingerprint([str(pkg)]) not in (first, edited)
    assert code_fingerprint([str(tmp_path / "missing")]) == code_fingerprint([])


def test_the_setup_hook_never_stops_a_worker(monkeypatch, tmp_path):
    import gc
    import importlib
    import sys

    monkeypatch.setattr(warm_pool, "PREIMPORT_MODULES", ("aerodaas.no_such_module", "json"))
    try:
        warm_pool.preimport()  # a failed import is left to the actor that needs the module
    finally:
        gc.unfreeze()  # this test process's objects go back to the collector (preimport freezes them)
    env = warm_pool.setup_hook_env(tmp_path / "hook")
    assert env["__RAY_WORKER_PROCESS_SETUP_HOOK_ENV_VAR"] == "aerodaas_warm_hook.preimport"
    assert env["PYTHONPATH"].split(os.pathsep)[0] == str(tmp_path / "hook")
    monkeypatch.syspath_prepend(str(tmp_path / "hook"))
    hook = importlib.import_module("aerodaas_warm_hook")
    # the framework does not import (an edit in progress): loading and running the hook still succeed
    monkeypatch.setitem(sys.modules, "aerodaas.clusters.warm_pool", None)
    hook.preimport()


def test_a_worker_counts_as_warm_only_once_its_hook_has_run(tmp_path):
    """Ray titles a worker ray::IDLE when it connects, before its setup hook imports the framework: the pool counts
    it idle only once the hook left its ready file, written after the worker started (a file left by an earlier
    process with the same pid does not count); files of ended workers are removed, and a new daemon starts empty."""
    import importlib
    import sys

    import psutil

    ready = tmp_path / "hook" / warm_pool.READY_DIR
    me = psutil.Process()
    warm_pool.setup_hook_env(tmp_path / "hook")
    assert not warm_pool.hook_done(ready, me.pid, me.create_time())  # connected, hook not run yet
    sys.path.insert(0, str(tmp_path / "hook"))
    try:
        sys.modules.pop(warm_pool.HOOK_MODULE, None)
        importlib.import_module(warm_pool.HOOK_MODULE).preimport()
    finally:
        sys.path.remove(str(tmp_path / "hook"))
        sys.modules.pop(warm_pool.HOOK_MODULE, None)
    assert warm_pool.hook_done(ready, me.pid, me.create_time())
    # the same pid, for a process started after the file was written: not this worker's file
    assert not warm_pool.hook_done(ready, me.pid, (ready / str(me.pid)).stat().st_mtime + 5.0)
    assert warm_pool.hook_done(None, me.pid, me.create_time())  # no hook configured: nothing to wait for
    (ready / "999999999").touch()
    warm_pool.forget_ended(ready, {me.pid})
    assert sorted(p.name for p in ready.iterdir()) == [str(me.pid)]
    warm_pool.setup_hook_env(tmp_path / "hook")  # a new daemon: its workers write their own
    assert list(ready.iterdir()) == []


def test_a_plugin_on_the_cluster_import_path_is_not_shipped(tmp_path):
    site = tmp_path / "site"
    (site / "plug").mkdir(parents=True)
    st = {"sys_path": ["", str(site)]}
    assert not importable_by_cluster(str(tmp_path / "cwd_plug"), {"sys_path": [""]})  # "" is no folder of theirs
    assert importable_by_cluster(str(site / "plug"), st)
    assert importable_by_cluster(str(site / "mod.py"), st)
    assert not importable_by_cluster(str(tmp_path / "elsewhere" / "plug"), st)
    assert not importable_by_cluster(str(site / "plug"), {})


def test_a_warm_worker_holds_the_follow_assignment_and_hides_its_imports_from_the_collector():
    """In a fresh interpreter, as in a warm worker: after the hook, the follow's track assignment (scipy.optimize)
    and the built-in analytics are imported and what the imports allocated is frozen, so that the actor's own set-up
    collection (``DataPlane.watch_gc``) scans only what the actor makes."""
    import subprocess
    import sys
    from pathlib import Path

    code = ("import gc, sys\n"
            "from aerodaas.clusters.warm_pool import preimport\n"
            "preimport()\n"
            "print('scipy.optimize' in sys.modules, 'aerodaas.actors.drone.component' in sys.modules, gc.get_freeze_count())\n"
            "print(all(m in sys.modules for m in ('aerodaas.analytics.detector', 'aerodaas.analytics.follow', "
            "'aerodaas.perception.decoders')))\n")
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    scipy_in, drone_in, frozen, analytics_in = out.stdout.split()
    assert analytics_in == "True", out.stdout  # the built-in analytics an actor's spec unpickles, and their set-up
    assert (scipy_in, drone_in) == ("True", "True"), out.stdout
    assert int(frozen) > 50_000, out.stdout  # the framework, Ray, numpy, OpenCV and scipy: about 115,000 objects


def test_a_warm_worker_keeps_rays_serialisation_addons_lean():
    """The warm workers' hook takes the place of the node's own (``aerodaas.clusters.worker_memory.worker_setup``)
    in the environment: in a fresh interpreter, as in a warm worker, after the hook Ray's serialisation add-ons (what
    the worker's first deserialisation of a run runs) neither import nor register pyarrow, Pydantic's v1 package or
    Starlette."""
    import subprocess
    import sys
    from pathlib import Path

    libraries = ("pyarrow", "pydantic.v1", "starlette")
    code = ("import sys\n"
            "from aerodaas.clusters.warm_pool import preimport\n"
            "from tests.runtime.test_worker_imports import _Context\n"
            "from ray.util import serialization_addons\n"
            "preimport()\n"
            "c = _Context(); serialization_addons.apply(c)\n"
            f"print(sorted(m for m in sys.modules if m.split('.')[0] in {libraries!r} and m.startswith({libraries!r})))\n"
            f"print(sorted(r for r in c.registered if r.startswith({libraries!r})))\n")
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.splitlines() == ["[]", "[]"], out.stdout
