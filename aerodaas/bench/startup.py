"""``aerodaas bench startup``: seconds from ``aerodaas run APP`` to the first frame an analytics has processed.

Each repetition starts ``aerodaas run APP --quiet`` as a fresh process (a cold Ray start included) with
``AERODAAS_STARTUP_PROBE`` naming a file; the runtime appends ``<phase> <unix time>`` lines to it
(:func:`aerodaas.startup_probe.probe`; ``cli``: the command started, ``app_built``: the application's dataflow is built,
``ray_ready``, ``hosts_ready``: every host set up and wired, ``first_processed``: the first item an analytics finished).
The run is then interrupted.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from aerodaas.startup_probe import PROBE_ENV


def _read(path: Path) -> dict[str, float]:
    out: dict[str, float] = {}
    if path.exists():
        for line in path.read_text().splitlines():
            name, _, t = line.partition(" ")
            if name and t:
                out.setdefault(name, float(t))
    return out


def measure_once(app: str, timeout_s: float = 120.0) -> dict:
    """One cold start of ``aerodaas run app``. Raises RuntimeError if no frame was processed in ``timeout_s``."""
    exe = shutil.which("aerodaas")
    cmd = [exe] if exe else [sys.executable, "-m", "aerodaas.cli"]
    with tempfile.TemporaryDirectory() as d:
        pf = Path(d) / "probe.txt"
        env = dict(os.environ, **{PROBE_ENV: str(pf)})
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
    return {"seconds_to_first_frame": rel["first_processed"], "phases_s": rel}


def run_startup(app: str, repeat: int = 3) -> dict:
    from . import machine_info

    runs = []
    for i in range(repeat):
        r = measure_once(app)
        print(f"startup run {i + 1}/{repeat}: {r['seconds_to_first_frame']:.2f} s  {r['phases_s']}", file=sys.stderr,
              flush=True)
        runs.append(r)
    secs = [r["seconds_to_first_frame"] for r in runs]
    return {"benchmark": "startup", "machine": machine_info(), "app": app, "seconds_to_first_frame": statistics.median(secs),
            "min_s": min(secs), "max_s": max(secs), "runs": runs, "target_s": 6.0}


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("startup", help="seconds from `aerodaas run APP` to the first processed frame (cold Ray)")
    p.add_argument("--app", default=None, help="application (default: apps/vehicle_tracking.py next to this install)")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--json", action="store_true", help="print the JSON report")
    p.add_argument("--out", help="also write the JSON report to this file")

    def run(a: argparse.Namespace) -> int:
        app = a.app or str(Path(__file__).resolve().parents[2] / "apps" / "vehicle_tracking.py")
        if not Path(app).is_file():
            print(f"aerodaas bench startup: application {app!r} not found (give --app)", file=sys.stderr)
            return 2
        if a.repeat < 1:
            print(f"aerodaas bench startup: --repeat must be >= 1, got {a.repeat}", file=sys.stderr)
            return 2
        try:
            report = run_startup(app, a.repeat)
        except RuntimeError as e:
            print(f"aerodaas bench startup: {e}", file=sys.stderr)
            return 1
        text = json.dumps(report, indent=2)
        if a.out:
            Path(a.out).write_text(text)
        if a.json:
            print(text)
        return 0

    p.set_defaults(func=run)
