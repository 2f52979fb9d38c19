"""What a same-node channel's shared memory costs each process that makes a segment: N fresh interpreters each create
one 1 MiB segment, with CPython's ``multiprocessing.shared_memory.SharedMemory`` (before Python 3.13 it starts a
resource-tracker interpreter per process) or with ``aerodaas.actors.data.channel_slots.create_segment`` (none); the
report is the processes below this one and their summed PSS, as JSON.

    python docs/bench/shm_tracker_cost.py [N]
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import psutil

from aerodaas.clusters.reaper import sweep_segments

MAKERS = {
    "SharedMemory": "from multiprocessing.shared_memory import SharedMemory\ns = SharedMemory(create=True, size=1 << 20)\n",
    "create_segment": "from aerodaas.actors.data.channel_slots import create_segment\ns = create_segment(1 << 20)\n",
}


def measure(maker: str, n: int) -> dict:
    """``n`` processes holding one segment each, made by ``maker`` (a key of :data:`MAKERS`): their count with
    their children, and PSS in MiB (all, and per segment-making process)."""
    code = "import time\n" + MAKERS[maker] + "print('ready', flush=True)\ntime.sleep(120)\n"
    procs = [subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True) for _ in range(n)]
    try:
        for p in procs:
            p.stdout.readline()
        time.sleep(1.0)  # every tracker started
        below = psutil.Process().children(recursive=True)
        pss = sum(p.memory_full_info().pss for p in below) / 2**20
        return {"maker": maker, "segment_makers": n, "processes": len(below), "pss_mib": round(pss, 1),
                "pss_mib_per_maker": round(pss / n, 2)}
    finally:
        for p in procs:
            p.kill()
            p.wait()
        sweep_segments({p.pid for p in procs})


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    print(json.dumps({"python": sys.version.split()[0], "cpu_count": os.cpu_count(), "load_1min": os.getloadavg()[0],
                      "rows": [measure(m, n) for m in MAKERS]}, indent=1))
