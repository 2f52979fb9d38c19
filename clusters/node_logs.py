"""What a local Ray node that failed to start left behind: whether its raylet and GCS were still running, and the
last lines of their log files. Printed with the warning of a node start that is tried again
(:mod:`aerodaas.runtime.ray_start`, the daemon of ``aerodaas up``), so that a start which timed out says whether the
raylet died or was only slow to register.

Where Ray keeps them (Ray 2.60, ``ray/_private/node.py``): a node started by process ``pid`` gets the session folder
``<temp dir>/session_<date>_<time>_<microseconds>_<pid>``; its ``logs/`` folder holds ``raylet.out``,
``raylet.err``, ``gcs_server.out`` and ``gcs_server.err``. Ray then waits a fixed 30 s for the raylet to register with
the GCS and raises "The current node timed out during startup" — it deletes nothing.
"""
from __future__ import annotations

import os

__all__ = ["LOG_FILES", "NODE_PROCESSES", "default_temp_dir", "failed_start_report", "session_dir_of"]

#: the node's log files worth reading after a failed start, in the order they are reported
LOG_FILES = ("raylet.err", "raylet.out", "gcs_server.err", "gcs_server.out")
#: the node processes whose state is reported (their ``/proc/<pid>/comm``)
NODE_PROCESSES = ("raylet", "gcs_server")


def default_temp_dir() -> str:
    """Ray's temp folder when none is given: ``$RAY_TMPDIR``, else ``$TMPDIR``, else ``/tmp``, + ``/ray``
    (``ray/_common/utils.py``, ``get_default_ray_temp_dir``, on Linux)."""
    return os.path.join(os.environ.get("RAY_TMPDIR") or os.environ.get("TMPDIR") or "/tmp", "ray")


def session_dir_of(temp_dir: str, pid: int, since_s: float) -> str | None:
    """The newest session folder in ``temp_dir`` that process ``pid`` made (its name ends ``_<pid>``) and that was
    modified at ``since_s`` (seconds since the epoch) or later, one second of slack; None when there is none (other
    processes' sessions in the same temp dir are never chosen)."""
    try:
        names = [n for n in os.listdir(temp_dir) if n.startswith("session_2") and n.endswith(f"_{pid}")]
    except OSError:
        return None
    found = []
    for name in names:
        path = os.path.join(temp_dir, name)
        try:
            mtime = os.stat(path).st_mtime
        except OSError:
            continue
        if mtime >= since_s - 1.0:
            found.append((mtime, path))
    return max(found)[1] if found else None


def _comm(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/comm", encoding="utf-8", errors="replace") as f:
            return f.read().strip()
    except OSError:
        return ""


def _tail(path: str, lines: int, max_bytes: int) -> list[str]:
    """The last ``lines`` non-empty lines of ``path`` (reading at most its last ``max_bytes``), each cut to 240
    characters; [] when the file is missing or empty."""
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            size = f.tell()
            f.seek(max(0, size - max_bytes))
            data = f.read(max_bytes)
    except OSError:
        return []
    text = data.decode("utf-8", errors="replace").splitlines()
    return [ln[:240] for ln in text if ln.strip()][-lines:]


def failed_start_report(temp_dir: str, pid: int, since_s: float, new_pids: list[int], lines: int = 8,
                        max_bytes: int = 65536) -> str:
    """A few lines on a node start that failed: for each of the raylet and the GCS, whether a process of that name
    among ``new_pids`` (the processes the attempt started) was still running; then, from the attempt's session
    folder (:func:`session_dir_of`), the last ``lines`` lines of each non-empty file of :data:`LOG_FILES`, reading
    at most ``max_bytes`` of each. Bounded in time and size; never raises for a missing file or process."""
    running = {_comm(p) for p in new_pids}
    out = ["Ray node processes at the failure: " + ", ".join(
        f"{name} {'running' if name in running else 'not running'}" for name in NODE_PROCESSES)]
    session = session_dir_of(temp_dir, pid, since_s)
    if session is None:
        out.append(f"no session folder of process {pid} in {temp_dir}")
        return "\n".join(out)
    for name in LOG_FILES:
        path = os.path.join(session, "logs", name)
        tail = _tail(path, lines, max_bytes)
        if tail:
            out.append(f"last lines of {path}:")
            out += ["    " + ln for ln in tail]
    if len(out) == 1:
        out.append(f"the node's log files in {session}/logs are empty or missing")
    return "\n".join(out)
