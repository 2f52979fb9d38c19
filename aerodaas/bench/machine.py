"""Where a benchmark ran (:func:`machine_info`), recorded in every benchmark's report."""
from __future__ import annotations

import os
import platform
import sys
from importlib.metadata import PackageNotFoundError, version

import psutil


def machine_info() -> dict:
    """Where a benchmark ran: CPU count (and the CPUs this process may use), total memory in GiB, the 1-minute
    load average when the benchmark started (a busy machine shows here), Python version and implementation, Ray's
    version, platform string, processor."""
    try:
        ray_version = version("ray")
    except PackageNotFoundError:
        ray_version = None
    return {
        "cpu_count": os.cpu_count(),
        "cpus_usable": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
        "memory_gib": round(psutil.virtual_memory().total / 2**30, 1),
        "load_avg_1min": round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None,
        "python": platform.python_version(),
        "implementation": platform.python_implementation(),
        "ray": ray_version,
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "executable": sys.executable,
    }
