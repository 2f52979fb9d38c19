"""The startup probe: when ``AERODAAS_STARTUP_PROBE`` names a file, the CLI, the runtime and the hosts append
``<phase> <unix time>`` lines to it (``cli``, ``app_built``, ``ray_ready``, ``hosts_ready``, ``first_processed``),
which ``aerodaas bench startup`` (:mod:`aerodaas.bench.startup`) reads. Production code calls :func:`probe`; it
lives here so that production code never imports the benchmarks."""
from __future__ import annotations

import os
import time

__all__ = ["PROBE_ENV", "probe"]

PROBE_ENV = "AERODAAS_STARTUP_PROBE"


def probe(phase: str) -> None:
    """Append ``phase`` with the current unix time to the startup probe file, if one is set (never raises)."""
    path = os.environ.get(PROBE_ENV)
    if path:
        try:
            with open(path, "a") as f:
                f.write(f"{phase} {time.time():.6f}\n")
        except OSError:
            pass
