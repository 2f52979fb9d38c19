"""The log monitor of the Ray nodes AeroDaaS starts on this machine: fewer listings of the logs folder when idle.

Each Ray node runs a log monitor (``ray/_private/log_monitor.py``, Ray 2.60) that sends the output of the node's
workers to the drivers (an actor's ``print`` on the console of ``aerodaas run``). When it has nothing to send it
polls every 0.1 s, and each poll lists the logs folder (``update_log_filenames``: a ``glob`` per pattern and a
``stat`` per matching file) besides looking at every file it follows. Every run starts its actors in new workers,
each with its own log files, so on a node that serves many runs (``aerodaas up``, the shared session of a test
worker) each listing costs more than the last.

:func:`lean_log_monitor` puts Ray's own ``RAY_LOG_MONITOR_MANY_FILES_THRESHOLD=0`` into this process's environment,
where it stays for the process's life and reaches every Ray node process the process starts (local mode,
``aerodaas up``, :class:`~aerodaas.clusters.local.LocalCluster`; read by the monitor's module when it starts): the
logs folder is then listed at most every ``LOG_NAME_UPDATE_INTERVAL_S`` (0.5 s) instead of at every poll. A new
worker's first line reaches the console up to 0.5 s later; no line is left out (a file found later is read from its
start). Ray's limit of open files (``RAY_LOG_MONITOR_MAX_OPEN_FILES``, 200) is left as it is: when it is reached the
monitor closes every file without reading what is left in it and sets aside the files of workers that have ended, so
a lower limit would risk the last lines of an actor that ends at that moment.

A value the user already set is kept; ``AERODAAS_LEAN_LOG_MONITOR=0`` leaves Ray's default. What it saves:
``docs/results/test-tiers.md``.
"""
from __future__ import annotations

import os

__all__ = ["SETTINGS", "lean_log_monitor"]

#: what :func:`lean_log_monitor` sets: Ray's environment variable → value
SETTINGS = {"RAY_LOG_MONITOR_MANY_FILES_THRESHOLD": "0"}


def lean_log_monitor() -> bool:
    """Put each of :data:`SETTINGS` into this process's environment for the Ray node processes it is about to start
    (local mode, ``aerodaas up``, :class:`~aerodaas.clusters.local.LocalCluster`), unless the user set it; nothing
    when ``AERODAAS_LEAN_LOG_MONITOR`` is ``0``. Returns True when every one is in effect for children."""
    if os.environ.get("AERODAAS_LEAN_LOG_MONITOR", "").strip() == "0":
        return False
    in_effect = [os.environ.setdefault(k, v) == v for k, v in SETTINGS.items()]
    return all(in_effect)
