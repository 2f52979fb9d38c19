"""The C heap of the Ray processes AeroDaaS starts on this machine: at most two glibc malloc arenas per process.

glibc gives every thread that allocates its own malloc arena, up to eight per core; a drone actor runs a dozen
threads (Ray's threaded-actor executor, the data plane's pools, the camera and control loops), and each arena
keeps 1-3 MB of freed memory. ``MALLOC_ARENA_MAX=2`` (glibc ``mallopt(M_ARENA_MAX)``, read when a process starts,
so it must be in the environment of the node processes before they are launched, which their workers inherit)
caps that. Measured with ``aerodaas bench fleet --drones 1 --drones 20 --duration 20`` on the 2-core CI machine
kind: 88-91 MB of PSS per extra drone actor without it, 77 MB with it, missed control ticks 0.07-0.25 % and
0.02 %. A value the user already set is kept; ``AERODAAS_MALLOC_ARENA_MAX=0`` leaves glibc's default.
"""
from __future__ import annotations

import os

__all__ = ["ARENAS", "limit_malloc_arenas"]

#: glibc malloc arenas per process of the Ray nodes AeroDaaS starts
ARENAS = 2


def limit_malloc_arenas() -> bool:
    """Put ``MALLOC_ARENA_MAX`` (:data:`ARENAS`) into this process's environment, for the Ray node processes it is
    about to start (local mode, ``aerodaas up``, :class:`~aerodaas.clusters.local.LocalCluster`), unless the user
    set it or ``AERODAAS_MALLOC_ARENA_MAX`` is ``0``. Returns True when the variable is now in effect for children."""
    if os.environ.get("AERODAAS_MALLOC_ARENA_MAX", "").strip() == "0":
        return False
    os.environ.setdefault("MALLOC_ARENA_MAX", str(ARENAS))
    return True
