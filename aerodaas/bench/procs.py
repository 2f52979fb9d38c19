"""Process accounting for the benchmarks: every process of the local Ray runtime (GCS, raylet, dashboard and
runtime-env agents, monitors, workers) plus the driver, with their memory (RSS, and PSS, which splits shared
pages fairly) and CPU time, via psutil."""
from __future__ import annotations

import os
import threading
import time
from typing import Any

import psutil
import ray


def ray_processes(nodes: list | None = None, exclude: tuple[int, ...] = ()) -> list:
    """psutil.Process objects of this driver's local Ray node — or of ``nodes`` (``ray._private.node.Node``
    handles, e.g. a :class:`~aerodaas.clusters.local.LocalCluster`'s) — (their system processes and all their
    descendants) and of the driver itself, but the processes ``exclude`` names (pids: a benchmark's own baseline
    actor). Raises RuntimeError when Ray was not started by this driver and no ``nodes`` are given."""
    if nodes is None:
        node = getattr(ray._private.worker, "_global_node", None)
        if node is None:
            raise RuntimeError("ray_processes(): Ray is not running in this process (call ray.init first)")
        nodes = [node]
    procs: dict[int, Any] = {os.getpid(): psutil.Process()}
    for info in (i for n in nodes for infos in n.all_processes.values() for i in infos):
        try:
            p = psutil.Process(info.process.pid)
        except psutil.NoSuchProcess:
            continue
        procs[p.pid] = p
        for c in p.children(recursive=True):
            procs[c.pid] = c
    return [p for pid, p in procs.items() if pid not in exclude]


def memory_mb(procs: list | None = None) -> dict[str, Any]:
    """Summed RSS and PSS (MiB) of ``procs`` (default: :func:`ray_processes`), and per-process rows."""
    rows, rss, pss = [], 0.0, 0.0
    for p in procs if procs is not None else ray_processes():
        try:
            mi = p.memory_full_info()
            name = " ".join(p.cmdline()[:1]) if p.pid != os.getpid() else "driver"
            title = p.name()
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            continue
        rss += mi.rss / 2**20
        pss += getattr(mi, "pss", mi.rss) / 2**20
        rows.append({"pid": p.pid, "name": title if title.startswith("ray::") else os.path.basename(name) or title,
                     "rss_mb": round(mi.rss / 2**20, 1), "pss_mb": round(getattr(mi, "pss", mi.rss) / 2**20, 1)})
    workers = sum(1 for r in rows if r["name"].startswith("ray::") and not r["name"].startswith("ray::IDLE")
                  and "Agent" not in r["name"])
    return {"rss_mb": rss, "pss_mb": pss, "processes": len(rows), "worker_processes": workers, "rows": rows}


def cpu_seconds(procs: list) -> float:
    """User + system CPU seconds consumed so far by ``procs`` (processes that exited are skipped)."""
    total = 0.0
    for p in procs:
        try:
            t = p.cpu_times()
            total += t.user + t.system
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            continue
    return total


class MemorySampler:
    """Samples :func:`memory_mb` every ``period_s`` seconds in a background thread (of :func:`ray_processes` of
    ``nodes``, without ``exclude``); keeps the peak sum."""

    def __init__(self, period_s: float = 1.0, nodes: list | None = None, exclude: tuple[int, ...] = ()) -> None:
        self.period_s, self.nodes, self.exclude = period_s, nodes, exclude
        self.peak: dict[str, Any] = {"rss_mb": 0.0, "pss_mb": 0.0, "processes": 0, "worker_processes": 0, "rows": []}
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._loop, daemon=True)

    def _loop(self) -> None:
        while not self._stop.is_set():
            try:
                m = memory_mb(ray_processes(self.nodes, self.exclude))
            except Exception:
                m = None
            if m and m["rss_mb"] > self.peak["rss_mb"]:
                self.peak = m
            self._stop.wait(self.period_s)

    def __enter__(self) -> "MemorySampler":
        self._t.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self._stop.set()
        self._t.join(5)
