"""A local Ray node's own processes started ahead of the load on the machine, its workers at the driver's priority.

A raylet starts two Python agents (the dashboard agent, ``ray/dashboard/agent.py``, and the runtime-environment
agent) and waits for each to write its port file into the session folder. Ray 2.60 waits a fixed 15 s per file
(``NodeManager::WaitForDashboardAgentPorts`` / ``WaitForPersistedPort``, ``src/ray/raylet/node_manager.cc``; no
setting) and then aborts (``raylet.err``: "Check failed ... Timed out waiting for file .../metrics_agent_port_...");
``ray.init`` reports "The current node timed out during startup" when its own 30 s pass. The dashboard agent needs
about 1 CPU-s to get there (imports, its gRPC server); on the 2-core machine kind at a 1-minute load of 16-18, every
process at the default priority, it did not get that in 15 s, three attempts in a row.

:func:`raised_node_priority` lowers the niceness of the thread that starts the node by :data:`NODE_NICE_DELTA` for
the start only: the GCS, the raylet and the log monitor it starts inherit that (Linux keeps a niceness per thread;
``fork`` copies the calling thread's), and so do the raylet's agents and workers. Each worker then returns, all its
threads, to the niceness the driver had (:func:`reset_worker_priority`, called by the workers' setup hook
:func:`aerodaas.clusters.worker_memory.worker_setup`, which reads it from :data:`WORKER_NICE_ENV`): the run's actors
compete as before, and only Ray's mostly idle node processes keep the higher priority. Lowering a niceness needs
``CAP_SYS_NICE`` (root); without it nothing changes. ``AERODAAS_NODE_NICE=0`` turns it off.
"""
from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Iterator

__all__ = ["NODE_NICE_DELTA", "WORKER_NICE_ENV", "raised_node_priority", "reset_worker_priority"]

#: how much lower the niceness of a local Ray node's processes starts than the driver's (-5: CFS weight 3,121 against
#: 1,024 at niceness 0, ``kernel/sched/core.c`` ``sched_prio_to_weight``)
NODE_NICE_DELTA = -5
#: the environment variable (inherited by the raylet and its workers) holding the niceness a worker returns to
WORKER_NICE_ENV = "AERODAAS_WORKER_NICE"

_lock = threading.Lock()


@contextlib.contextmanager
def raised_node_priority() -> Iterator[bool]:
    """Within the block, processes that this thread starts run :data:`NODE_NICE_DELTA` below this thread's
    niceness, and :data:`WORKER_NICE_ENV` holds this thread's niceness for the workers to return to (see the
    module). Yields True when in effect; False (nothing changed) when not permitted (no ``CAP_SYS_NICE``) or
    ``AERODAAS_NODE_NICE`` is ``0``. On leaving, this thread and the threads this process started in the block
    are set back to the thread's niceness. Not re-entrant across threads: a second block waits."""
    if os.environ.get("AERODAAS_NODE_NICE", "").strip() == "0":
        yield False
        return
    with _lock:
        tid = threading.get_native_id()
        before = os.getpriority(os.PRIO_PROCESS, tid)
        try:
            os.setpriority(os.PRIO_PROCESS, tid, before + NODE_NICE_DELTA)
        except OSError:  # EACCES/EPERM: not permitted to lower a niceness; the node starts as it would have
            yield False
            return
        os.environ[WORKER_NICE_ENV] = str(before)
        threads = set(os.listdir("/proc/self/task"))
        try:
            yield True
        finally:
            # this thread, and the threads it started meanwhile in this process (``ray.init``'s own: the driver's
            # core worker and gRPC threads), back at the thread's niceness
            for t in [tid, *(int(t) for t in set(os.listdir("/proc/self/task")) - threads)]:
                with contextlib.suppress(OSError):  # a thread that ended meanwhile
                    os.setpriority(os.PRIO_PROCESS, t, before)


def reset_worker_priority() -> bool:
    """In a Ray worker: every thread of this process to the niceness in :data:`WORKER_NICE_ENV` (raising a
    niceness is always permitted). Returns True when the variable was set and every thread took it."""
    target = os.environ.get(WORKER_NICE_ENV, "").strip()
    if not target:
        return False
    ok = True
    for tid in os.listdir("/proc/self/task"):
        try:
            os.setpriority(os.PRIO_PROCESS, int(tid), int(target))
        except (OSError, ValueError):  # a thread that ended meanwhile, or a value that is no niceness
            ok = False
    return ok
