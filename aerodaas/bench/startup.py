"""``aerodaas bench startup``: seconds from ``aerodaas run APP`` to the first frame an analytics has processed.

Each repetition starts ``aerodaas run APP --quiet`` as a fresh process (a cold Ray start included) with
``AERODAAS_STARTUP_PROBE`` naming a file; the runtime appends ``<phase> <unix time>`` lines to it
(:func:`aerodaas.protocol.startup_probe.probe`; ``cli``: the command started, ``app_built``: the application's dataflow is built,
``ray_ready``, ``hosts_ready``: every host set up and wired, ``first_processed``: the first item an analytics finished).
The run is then interrupted.

Two modes (``--mode``): ``cold`` (the run starts its own Ray; ``AERODAAS_NO_ATTACH=1``) and ``attached`` (the run
attaches to a persistent local cluster of ``aerodaas up``, started here under a private ``AERODAAS_STATE_DIR`` with
the probe file in its environment, since its workers write ``first_processed``, and stopped afterwards; a cluster the
user started is never touched). Each attached run starts once the cluster's warm pool is full again
(``warm_idle_at_start`` in the run's record), as when a user starts the next run a few seconds after the last. The
report holds both and the load average before and after (the machine may be shared).
"""
from __future__ import annotations

import argparse
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from rich.console import Console
from rich.progress import Progress

from aerodaas.bench.machine import machine_info
from aerodaas.bench.output import emit_report
from aerodaas.clusters import persistent
from aerodaas.clusters.persistent import read_state
from aerodaas.protocol.startup_probe import PROBE_ENV


#: the start-up phases every run reports (``detail_s`` has the rest: ``actors_created`` when the driver has asked Ray
#: for every actor, ``actor_init:<id>`` when an actor's constructor ran, ``actor_setup:<id>`` when its components
#: were built)
PHASES = ("cli", "app_built", "ray_ready", "hosts_ready", "first_processed")


def _read(path: Path) -> dict[str, float]:
    out: dict[str, float] = {}
    if path.exists():
        for line in path.read_text().splitlines():
            name, _, t = line.partition(" ")
            if name and t:
                out.setdefault(name, float(t))
    return out


def measure_once(app: str, timeout_s: float = 120.0, attach: bool = False, probe_file: Path | None = None) -> dict:
    """One start of ``aerodaas run app`` (cold, or ``attach``-ed to ``aerodaas up``'s cluster, whose workers write
    to ``probe_file``). Raises RuntimeError if no frame was processed in ``timeout_s``."""
    exe = shutil.which("aerodaas")
    cmd = [exe] if exe else [sys.executable, "-m", "aerodaas.cli"]
    with tempfile.TemporaryDirectory() as d:
        pf = probe_file or Path(d) / "probe.txt"
        pf.write_text("")
        env = dict(os.environ, **{PROBE_ENV: str(pf)})
        if attach:
            env.pop("AERODAAS_NO_ATTACH", None)
        else:
            env["AERODAAS_NO_ATTACH"] = "1"
        t0 = time.time()
        proc = subprocess.Popen(cmd + ["run", app, "--quiet", "--timeout", str(timeout_s)], env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        try:
            while "first_processed" not in _read(pf):
                if proc.poll() is not None:
                    raise RuntimeError(f"aerodaas run {app} exited ({proc.returncode}) before processing a frame: "
                                       f"{(proc.stderr.read() or '')[-800:]}")
                if time.time() - t0 > timeout_s:
                    raise RuntimeError(f"no frame processed within {timeout_s:.0f} s")
                time.sleep(0.02)
            phases = _read(pf)
        finally:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                try:
                    proc.wait(60)
                except subprocess.TimeoutExpired:
                    proc.kill()
    rel = {k: round(v - t0, 3) for k, v in sorted(phases.items(), key=lambda kv: kv[1])}
    main = {k: v for k, v in rel.items() if k in PHASES}
    return {"seconds_to_first_frame": rel["first_processed"], "phases_s": main,
            "detail_s": {k: v for k, v in rel.items() if k not in PHASES}}


def _await_warm_pool(timeout_s: float = 60.0) -> int:
    """Wait (at most ``timeout_s``) until the attached cluster's warm pool is full, as it is when a user starts the
    next run some seconds after the last one; returns the idle warm workers then (0 when it keeps none)."""
    t_end = time.monotonic() + timeout_s
    while True:
        st = read_state() or {}
        idle, want = int(st.get("warm_idle", 0)), int(st.get("warm_workers", 0))
        if idle >= want or time.monotonic() > t_end:
            return idle
        time.sleep(0.2)


def _measure(app: str, repeat: int, attach: bool, progress, task, probe_file: Path | None = None) -> dict:
    runs = []
    for i in range(repeat):
        warm = _await_warm_pool() if attach else None
        r = measure_once(app, attach=attach, probe_file=probe_file)
        if warm is not None:
            r["warm_idle_at_start"] = warm
        progress.console.print(f"startup {'attached' if attach else 'cold'} run {i + 1}/{repeat}: "
                               f"{r['seconds_to_first_frame']:.2f} s  {r['phases_s']}")
        progress.advance(task)
        runs.append(r)
    secs = [r["seconds_to_first_frame"] for r in runs]
    return {"seconds_to_first_frame": statistics.median(secs), "min_s": min(secs), "max_s": max(secs), "runs": runs,
            "target_s": 1.0 if attach else 4.0}


def run_startup(app: str, repeat: int = 3, mode: str = "both", warm_workers: int | None = None) -> dict:
    load_before = os.getloadavg()
    out: dict = {"benchmark": "startup", "machine": machine_info(), "app": app}
    modes = ["cold", "attached"] if mode == "both" else [mode]
    with Progress(transient=True, console=Console(stderr=True)) as progress:
        task = progress.add_task("bench startup", total=repeat * len(modes))
        if "cold" in modes:
            out["cold"] = _measure(app, repeat, False, progress, task)
        if "attached" in modes:
            saved = {k: os.environ.get(k) for k in ("AERODAAS_STATE_DIR", PROBE_ENV)}
            with tempfile.TemporaryDirectory() as d:
                os.environ["AERODAAS_STATE_DIR"], os.environ[PROBE_ENV] = d, str(Path(d) / "probe.txt")
                try:
                    t_up = time.monotonic()
                    warm = persistent.DEFAULT_WARM_WORKERS if warm_workers is None else warm_workers
                    persistent.up(warm_workers=warm)
                    up_s = time.monotonic() - t_up
                    try:
                        out["attached"] = _measure(app, repeat, True, progress, task, Path(d) / "probe.txt")
                        out["attached"].update(aerodaas_up_s=round(up_s, 3), warm_workers=warm)
                    finally:
                        persistent.down()
                finally:
                    for k, v in saved.items():
                        if v is None:
                            os.environ.pop(k, None)
                        else:
                            os.environ[k] = v
    first = out[modes[0]]
    out.update(seconds_to_first_frame=first["seconds_to_first_frame"], min_s=first["min_s"], max_s=first["max_s"],
               runs=first["runs"], target_s=first["target_s"])
    out["load_avg_before"], out["load_avg_after"] = load_before, os.getloadavg()
    return out


def main(a: argparse.Namespace) -> int:
    """``aerodaas bench startup`` with the options of :mod:`aerodaas.bench.parsers`: checks them (exit 2 naming a bad
    one), runs the benchmark and prints its report; returns the exit code."""
    app = a.app or str(Path(__file__).resolve().parents[2] / "apps" / "vehicle_tracking.py")
    if not Path(app).is_file():
        print(f"aerodaas bench startup: application {app!r} not found (give --app)", file=sys.stderr)
        return 2
    if a.repeat < 1:
        print(f"aerodaas bench startup: --repeat must be >= 1, got {a.repeat}", file=sys.stderr)
        return 2
    if a.warm_workers is not None and not 0 <= a.warm_workers <= 64:
        print(f"aerodaas bench startup: --warm-workers must be in [0, 64], got {a.warm_workers}", file=sys.stderr)
        return 2
    try:
        report = run_startup(app, a.repeat, a.mode, a.warm_workers)
    except RuntimeError as e:
        print(f"aerodaas bench startup: {e}", file=sys.stderr)
        return 1

    emit_report(report, a.out, a.json)
    return 0
