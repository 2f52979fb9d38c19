"""The warm driver's process, as the daemon of ``aerodaas up`` runs it (:mod:`aerodaas.clusters.persistent`): started
once the node is up, with the environment of the shell that ran ``aerodaas up``, waited for until it listens, and
stopped before the node. ``AERODAAS_NO_WARM_DRIVER=1`` in that shell starts none."""
from __future__ import annotations

import os
import subprocess
import sys
import threading
import time

from aerodaas.clusters.warm_client import NO_WARM_DRIVER_ENV, socket_path

__all__ = ["READY_TIMEOUT_S", "start", "status", "stop"]

#: how long the daemon waits for the warm driver's imports before it reports the cluster up without it
READY_TIMEOUT_S = 120.0


def start(env: dict[str, str], stopping: threading.Event) -> subprocess.Popen | None:
    """Start ``python -P -m aerodaas.clusters.warm_driver SOCKET DAEMON_PID`` with ``env`` (its output into the
    daemon's log) and wait until its socket exists (at most :data:`READY_TIMEOUT_S`, or until ``stopping`` is
    set). Returns the process, or None when ``env`` turns it off; a process that exited is returned as it is
    (:func:`status` tells)."""
    if env.get(NO_WARM_DRIVER_ENV) == "1":
        return None
    path = socket_path(env)
    try:
        os.unlink(path)  # a stale one from a daemon that was killed
    except OSError:
        pass
    proc = subprocess.Popen([sys.executable, "-P", "-m", "aerodaas.clusters.warm_driver", path, str(os.getpid())],
                            env=env, stdin=subprocess.DEVNULL, close_fds=True)
    t_end = time.monotonic() + READY_TIMEOUT_S
    while not os.path.exists(path) and proc.poll() is None and time.monotonic() < t_end and not stopping.is_set():
        time.sleep(0.05)
    return proc


def status(proc: subprocess.Popen | None) -> str:
    """What ``cluster.json`` says of the warm driver: ``listening`` (and its pid), ``off``, or why not."""
    if proc is None:
        return "off"
    if proc.poll() is not None:
        return f"exited ({proc.returncode}); see the cluster's log"
    return f"listening (pid {proc.pid})"


def stop(proc: subprocess.Popen | None, timeout_s: float = 20.0) -> None:
    """SIGTERM to the warm driver (it stops its runs and removes its socket), SIGKILL after ``timeout_s``."""
    if proc is None or proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
