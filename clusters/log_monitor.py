"""The log monitor of the Ray nodes AeroDaaS starts on this machine: its idle CPU kept flat as actors come and go.

Each Ray node runs a log monitor (``ray/_private/log_monitor.py``, Ray 2.60) that sends the output of the node's
workers to the drivers (an actor's ``print`` on the console of ``aerodaas run``). When it has nothing to send it
polls every 0.1 s, and each poll costs in proportion to every worker log file the node ever had: it lists the logs
folder (``update_log_filenames``, a ``glob`` per pattern and a ``stat`` per match), looks at the size of every file
not open (``open_closed_files``) and checks every open one for new lines. The files of ended workers leave the
list only when the monitor closes all its files, which it does when ``LOG_MONITOR_MAX_OPEN_FILES`` (200) are open.
Every run starts its actors in new workers, so on a node that serves many runs (``aerodaas up``, the shared session
of a test worker) the idle monitor grows costlier with each one.

:func:`lean_log_monitor` puts two of Ray's own settings into this process's environment, for the node processes
it is about to start (read by the log monitor when it starts, from ``ray._private.ray_constants`` and the monitor's
module):

* ``RAY_LOG_MONITOR_MANY_FILES_THRESHOLD=0``: the logs folder is listed at most every
  ``LOG_NAME_UPDATE_INTERVAL_S`` (0.5 s) instead of at every poll; a new worker's first line reaches the console up
  to 0.5 s later;
* ``RAY_LOG_MONITOR_MAX_OPEN_FILES`` = :data:`MAX_OPEN_FILES`: the monitor closes its files, and moves the files of
  ended workers to ``logs/old`` (as it does by default at 200), once that many are open.

A value the user already set is kept; ``AERODAAS_LEAN_LOG_MONITOR=0`` leaves Ray's defaults. What it saves:
``docs/results/test-tiers.md``.
"""
from __future__ import annotations

import os

__all__ = ["MAX_OPEN_FILES", "SETTINGS", "lean_log_monitor"]

#: the log monitor's open files before it closes them all and sets the ended workers' files aside
MAX_OPEN_FILES = 16
#: what :func:`lean_log_monitor` sets: Ray's environment variable → value
SETTINGS = {"RAY_LOG_MONITOR_MANY_FILES_THRESHOLD": "0", "RAY_LOG_MONITOR_MAX_OPEN_FILES": str(MAX_OPEN_FILES)}


def lean_log_monitor() -> bool:
    """Put :data:`SETTINGS` into this process's environment for the Ray node processes it is about to start (local
    mode, ``aerodaas up``, :class:`~aerodaas.clusters.local.LocalCluster`), each unless the user set it; nothing when
    ``AERODAAS_LEAN_LOG_MONITOR`` is ``0``. Returns True when both are in effect for children."""
    if os.environ.get("AERODAAS_LEAN_LOG_MONITOR", "").strip() == "0":
        return False
    return all(os.environ.setdefault(k, v) == v for k, v in SETTINGS.items())
