"""A local Ray node's agents started ahead of the load on the machine, so that its raylet does not give up on them.

A raylet starts two Python agents (the dashboard agent, ``ray/dashboard/agent.py``, and the runtime-environment
agent, ``ray/_private/runtime_env/agent/main.py``) and waits for each to write its port file into the session
folder. Ray 2.60 waits a fixed 15 s per file (``NodeManager::WaitForDashboardAgentPorts`` / ``WaitForPersistedPort``,
``src/ray/raylet/node_manager.cc``; no setting) and then aborts (``raylet.err``: "Check failed ... Timed out waiting
for file .../metrics_agent_port_..."); ``ray.init`` reports "The current node timed out during startup" when its own
30 s pass. The dashboard agent needs about 1 CPU-s to get there (imports, its gRPC server); on the 2-core machine kind
at a 1-minute load of 16-18, every process at the default priority, it did not get that in 15 s, three attempts in
a row.

:func:`agents_ahead` makes a node that ``ray.init`` or ``ray.cluster_utils.Cluster`` starts within it (``aerodaas
run``'s own Ray, ``aerodaas up``, :class:`~aerodaas.clusters.local.LocalCluster`) run both agents under ``nice -n``
:data:`AGENT_NICE_DELTA` (coreutils ``nice``, which then execs the agent: the raylet's pid bookkeeping and fate
sharing see the agent itself). The agents are idle but for a few polls once started; the GCS, the raylet, the log
monitor and the workers (the run's actors) keep their niceness. Lowering a niceness needs ``CAP_SYS_NICE`` (root);
without it nothing changes. ``AERODAAS_NODE_NICE=0`` turns it off.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import threading
from collections.abc import Iterator
from typing import Any

__all__ = ["AGENT_NICE_DELTA", "AGENTS", "agents_ahead", "may_lower_niceness"]

#: the niceness of a local Ray node's agents relative to their raylet (-5: CFS weight 3,121 against 1,024 at 0,
#: ``kernel/sched/core.c`` ``sched_prio_to_weight``)
AGENT_NICE_DELTA = -5
#: the component names Ray builds the agents' commands for (``ray._private.ray_constants.PROCESS_TYPE_*``)
AGENTS = ("dashboard_agent", "runtime_env_agent")
#: the function of ``ray._private.services`` that builds the start of each agent's command (Ray 2.60)
_BUILDER = "_build_python_executable_command_memory_profileable"

_lock = threading.Lock()


def may_lower_niceness() -> bool:
    """Whether this process may lower a niceness (``CAP_SYS_NICE``): tried on a short-lived thread of its own."""
    out: list[bool] = []

    def attempt() -> None:
        tid = threading.get_native_id()
        try:
            os.setpriority(os.PRIO_PROCESS, tid, os.getpriority(os.PRIO_PROCESS, tid) - 1)
            out.append(True)
        except OSError:
            out.append(False)

    t = threading.Thread(target=attempt, name="aerodaas-nice-probe")
    t.start()
    t.join()
    return out[0]


@contextlib.contextmanager
def agents_ahead() -> Iterator[bool]:
    """Within the block, a node that ``ray.init`` or ``ray.cluster_utils.Cluster`` starts in this process starts its
    agents (:data:`AGENTS`) at :data:`AGENT_NICE_DELTA` below the raylet's niceness (see the module). Yields True
    when in effect; False (nothing changed) when ``AERODAAS_NODE_NICE`` is ``0``, this process may not lower a
    niceness, there is no ``nice`` command, or this Ray has no such command builder. Ray's module is restored on
    leaving. Not re-entrant across threads: a second block waits."""
    nice = shutil.which("nice")
    if os.environ.get("AERODAAS_NODE_NICE", "").strip() == "0" or nice is None:
        yield False
        return
    try:
        from ray._private import services  # lazy: heavy ray
    except ImportError:
        yield False
        return
    build = getattr(services, _BUILDER, None)
    if not callable(build) or not may_lower_niceness():
        yield False
        return

    def ahead(component: str, *args: Any, **kwargs: Any) -> list[str]:
        cmd = build(component, *args, **kwargs)
        return [nice, "-n", str(AGENT_NICE_DELTA), *cmd] if component in AGENTS else cmd

    with _lock:
        setattr(services, _BUILDER, ahead)
        try:
            yield True
        finally:
            setattr(services, _BUILDER, build)
