"""The warm-worker pool of ``aerodaas up`` (aerodaas.clusters.warm_pool) without Ray: when it refills, when it throws
warm workers away (the framework's code changed), what it reports; the code fingerprint; the setup hook. The pool
on a real cluster, used by a real run, is tested in test_example_plugins (cluster group)."""
from __future__ import annotations

import os

from aerodaas.clusters import warm_pool
from aerodaas.clusters.persistent import importable_by_cluster
from aerodaas.clusters.warm_pool import WarmPool, code_fingerprint


class FakeRaylet:
    def __init__(self) -> None:
        self.idle: list[int] = []
        self.next_pid = 100
        self.stopped: list[int] = []
        self.prestarts: list[int] = []
        self.fp = "a"
        self.published: list[dict] = []

    def prestart(self, n: int) -> None:
        self.prestarts.append(n)
        for _ in range(min(n, 2)):  # the raylet starts at most its CPUs' worth per call (here 2)
            self.idle.append(self.next_pid)
            self.next_pid += 1

    def stop(self, pids: list[int]) -> None:
        for pid in pids:
            self.stopped.append(pid)
            self.idle.remove(pid)

    def pool(self, size: int = 3) -> WarmPool:
        return WarmPool(size=size, idle_pids=lambda: list(self.idle), prestart=self.prestart, stop_pids=self.stop,
                        fingerprint=lambda: self.fp, publish=self.published.append, settle_s=2.0)


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


def test_a_settled_code_change_stops_the_idle_warm_workers_and_refills_at_once():
    r = FakeRaylet()
    pool = r.pool(size=2)
    pool.step(0.0)
    old = list(r.idle)
    assert len(old) == 2
    r.fp = "b"  # a module file of the framework was edited ...
    pool.step(1.0)
    r.fp = "c"  # ... and another (a checkout touches many files): nothing happens until the code settles
    pool.step(2.0)
    pool.step(3.0)
    assert r.stopped == [] and r.published[-1]["code_fingerprint"] == "a"  # the workers still hold "a"
    pool.step(4.0)
    assert r.stopped == old and r.prestarts == [2, 2] and len(r.idle) == 2 and not set(old) & set(r.idle)
    assert r.published[-1]["code_fingerprint"] == "c"


def test_workers_that_do_not_stay_up_pause_the_pool():
    r = FakeRaylet()
    r.prestart = lambda n: r.prestarts.append(n)  # started, but they never become idle (their start fails)
    pool = r.pool(size=2)
    for k in range(20):
        pool.step(float(k))
    assert sum(r.prestarts) == 8 and "did not stay up" in pool.last_published["warm_error"]
    pool.step(25.0)
    assert sum(r.prestarts) == 8  # paused for crash_pause_s (30 s from t = 10)
    pool.step(40.0)
    pool.step(42.0)
    assert sum(r.prestarts) == 10  # then tried again, after settle_s


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
    import importlib
    import sys

    monkeypatch.setattr(warm_pool, "PREIMPORT_MODULES", ("aerodaas.no_such_module", "json"))
    warm_pool.preimport()  # a failed import is left to the actor that needs the module
    env = warm_pool.setup_hook_env(tmp_path / "hook")
    assert env["__RAY_WORKER_PROCESS_SETUP_HOOK_ENV_VAR"] == "aerodaas_warm_hook.preimport"
    assert env["PYTHONPATH"].split(os.pathsep)[0] == str(tmp_path / "hook")
    monkeypatch.syspath_prepend(str(tmp_path / "hook"))
    hook = importlib.import_module("aerodaas_warm_hook")
    # the framework does not import (an edit in progress): loading and running the hook still succeed
    monkeypatch.setitem(sys.modules, "aerodaas.clusters.warm_pool", None)
    hook.preimport()


def test_a_plugin_on_the_cluster_import_path_is_not_shipped(tmp_path):
    site = tmp_path / "site"
    (site / "plug").mkdir(parents=True)
    st = {"sys_path": ["", str(site)]}
    assert not importable_by_cluster(str(tmp_path / "cwd_plug"), {"sys_path": [""]})  # "" is no folder of theirs
    assert importable_by_cluster(str(site / "plug"), st)
    assert importable_by_cluster(str(site / "mod.py"), st)
    assert not importable_by_cluster(str(tmp_path / "elsewhere" / "plug"), st)
    assert not importable_by_cluster(str(site / "plug"), {})
