"""The niceness of a local Ray node's processes, read per thread from /proc: what
``aerodaas.clusters.node_priority`` sets (the raylet's two agents ahead of the load, everything else as started)."""
from __future__ import annotations

import os

from aerodaas.clusters import reaper
from aerodaas.clusters.node_priority import AGENT_NICE_DELTA, may_lower_niceness

#: the node's process kinds, by the first word of their command lines (the binaries' paths, the agents' process
#: titles), first match wins; a Ray worker still starting (no title yet) names ``.../sockets/raylet`` in its
#: arguments and is none of them
KINDS = ("gcs_server", "raylet", "DashboardAgent", "RuntimeEnvAgent")


def thread_nices(pid: int) -> list[int]:
    """The distinct niceness values of ``pid``'s threads (``/proc/PID/task/TID/stat`` field 19), sorted."""
    out = set()
    for tid in os.listdir(f"/proc/{pid}/task"):
        try:
            with open(f"/proc/{pid}/task/{tid}/stat") as f:
                out.add(int(f.read().rsplit(")", 1)[1].split()[16]))
        except OSError:
            pass
    return sorted(out)


def node_nices(root: int) -> dict[str, list[list[int]]]:
    """For each kind of :data:`KINDS`, the thread niceness values of every descendant of ``root`` of that kind."""
    out: dict[str, list[list[int]]] = {k: [] for k in KINDS}
    for pid in reaper.descendants(root):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                cmd = f.read().replace(b"\0", b" ").decode(errors="replace")
            nices = thread_nices(pid)
        except OSError:
            continue
        first = cmd.split(" ", 1)[0]  # .../raylet/raylet, .../gcs_server, ray::DashboardAgent, ...
        kind = next((k for k in KINDS if k in first), None)
        if kind is not None:
            out[kind].append(nices)
    return out


def expected_agent_nice(raylet_nice: int) -> int:
    """The agents' niceness beside a raylet at ``raylet_nice``: :data:`AGENT_NICE_DELTA` below it where this process
    may lower a niceness (root), else the same."""
    return raylet_nice + AGENT_NICE_DELTA if may_lower_niceness() else raylet_nice
