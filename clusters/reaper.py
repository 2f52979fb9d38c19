"""The run's process reaper: no process of a local run outlives its driver by more than a few seconds.

When ``aerodaas run`` starts its own Ray (local mode), Ray's node processes (GCS, raylet, the dashboard and
runtime-env agents, the workers that hold the actors) are descendants of the driver. If the driver dies without
``ray.shutdown`` (SIGKILL, the OOM killer), the raylet and workers go with it, but Ray's agents notice the raylet's
death, then try to report it to the dead GCS and wait out its client's timeout: measured here (Ray 2.60), the
dashboard and runtime-env agents of a SIGKILLed driver stayed 60-64 s (``ray/_private/process_watcher.py``,
``report_raylet_error_logs``).

The same holds for the POSIX shared-memory segments of the same-node channels (``/dev/shm/adc<pid>_<hex>``, named
by :func:`segment_prefix`): a segment is the sender's to unlink, and one that no process maps any more is removed
by :func:`sweep_segments` — by the reaper once the run's processes are gone, and by any process of ours that
creates a segment (``aerodaas.actors.data.channel_slots``), on any node. No resource-tracker process per actor is
started for them (CPython's ``multiprocessing.shared_memory`` starts one, a Python interpreter of about 7 MiB PSS,
in each process that creates or maps a segment before Python 3.13).

The reaper is a separate process started with the local Ray (:func:`start`), in its own session so that a
Ctrl-C to the driver's process group does not reach it. It runs this file as a script (standard library only,
~10 MB). Every ``period_s`` it records the driver's descendants as (pid, start time) pairs; once the driver is
gone it waits ``grace_s`` for them to end by themselves (``ray.shutdown`` normally ended them already), then
SIGKILLs those still alive whose start time still matches (a reused pid is never touched) and exits. It never
touches a process that was not below the driver: a cluster of ``aerodaas up`` or ``--address`` is not its to end.
"""
from __future__ import annotations

import argparse
import fcntl
import os
import re
import signal
import subprocess
import sys
import time

__all__ = ["SEGMENT_NAME", "SHM_DIR", "descendants", "ensure_started", "kill_started_since", "running_for",
           "segment_prefix", "start", "start_time", "started_since", "sweep_segments"]

#: where ``shm_open(3)`` keeps POSIX shared-memory segments on Linux (glibc: ``/dev/shm/<name>``)
SHM_DIR = "/dev/shm"
#: the name of a same-node channel's segment: :func:`segment_prefix` + 12 hex digits
SEGMENT_NAME = re.compile(r"adc(\d+)_[0-9a-f]{12}")


def segment_prefix(pid: int) -> str:
    """The name prefix of the shared-memory segments process ``pid`` creates for its same-node channels: ``adc`` +
    the pid + ``_``."""
    return f"adc{pid}_"


def sweep_segments(pids: set[int] | None = None, shm_dir: str = SHM_DIR) -> list[str]:
    """Unlink the channel segments (:data:`SEGMENT_NAME`) in ``shm_dir`` that no process maps any more (of the
    processes in ``pids`` by name, default: of any). Every process that creates or maps one holds a shared
    ``flock(2)`` on it for as long as it maps it (``aerodaas.actors.data.channel_slots.Segment``), so an exclusive
    lock taken without waiting means nobody does: a live process's segment is never unlinked, whatever its pid
    namespace, and a reused pid changes nothing. Returns the names unlinked; never raises."""
    try:
        names = os.listdir(shm_dir)
    except OSError:
        return []
    gone = []
    for name in names:
        m = SEGMENT_NAME.fullmatch(name)
        if m is None or (pids is not None and int(m.group(1)) not in pids):
            continue
        path = os.path.join(shm_dir, name)
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            if os.stat(path).st_ino == os.fstat(fd).st_ino:  # the name still names what was found unused
                os.unlink(path)
                gone.append(name)
        except OSError:  # mapped by a live process (the lock is held), or gone meanwhile
            pass
        finally:
            os.close(fd)
    return gone


def _stat_fields(pid: int | str) -> list[str] | None:
    """The fields of /proc/<pid>/stat after the command name (field 3, the state, first), or None when the process
    is gone or was caught while the kernel tears it down."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return fields if len(fields) >= 20 else None


def start_time(pid: int) -> int | None:
    """The start time of ``pid`` (clock ticks since boot, /proc/<pid>/stat field 22), or None if it has ended
    (or is a zombie)."""
    fields = _stat_fields(pid)
    if fields is None or fields[0] == "Z":
        return None
    try:
        return int(fields[19])
    except ValueError:
        return None


def descendants(root: int) -> list[int]:
    """Every process below ``root`` (from /proc's parent ids, /proc/<pid>/stat field 4), children before
    grandchildren."""
    children: dict[int, list[int]] = {}
    for d in os.listdir("/proc"):
        fields = _stat_fields(d) if d.isdigit() else None
        if fields is not None and fields[1].isdigit():
            children.setdefault(int(fields[1]), []).append(int(d))
    out, todo = [], [root]
    while todo:
        for c in children.get(todo.pop(0), []):
            out.append(c)
            todo.append(c)
    return out



def started_since(before: set[int]) -> list[int]:
    """This process's descendants that are not in ``before`` (pids from :func:`descendants` taken earlier): what
    was started meanwhile, e.g. by a Ray node start."""
    return [pid for pid in descendants(os.getpid()) if pid not in before]


def kill_started_since(before: set[int], marker: str = "") -> list[int]:
    """SIGKILL this process's descendants that are not in ``before`` (pids from :func:`descendants` taken earlier)
    and whose command line contains ``marker`` ("" matches all): what a failed Ray node start left behind (GCS,
    raylet, dashboard), which ``ray.shutdown()`` does not stop when the node never finished starting. Returns the
    pids signalled; a process already gone is skipped."""
    killed = []
    for pid in started_since(before):
        if marker.encode() not in b" ".join(_cmdline(pid)):
            continue
        try:
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)
        except ProcessLookupError:
            pass
    return killed

def start(driver_pid: int | None = None, period_s: float = 0.5, grace_s: float = 3.0) -> subprocess.Popen | None:
    """Start the reaper for ``driver_pid`` (default: this process). Returns its Popen, or None where there is no
    /proc (not Linux): nothing is reaped there."""
    if not os.path.isdir("/proc/self"):
        return None
    pid = os.getpid() if driver_pid is None else int(driver_pid)
    return subprocess.Popen([sys.executable, "-S", os.path.abspath(__file__), str(pid), str(period_s), str(grace_s)],
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True, close_fds=True)


def ensure_started() -> subprocess.Popen | None:
    """:func:`start` for this process unless its reaper already runs (called before a local Ray starts): one
    reaper per process, a forked child gets its own. Returns the Popen of the reaper started, None when one was
    running already (or where there is no /proc). Whether one runs is read from the process table
    (:func:`running_for`), not kept in a module-level table: the caller that starts one holds its Popen."""
    me = os.getpid()
    if running_for(me):
        return None
    return start(me)


def _children(pid: int) -> list[int]:
    """The child processes of ``pid``: ``/proc/<pid>/task/<tid>/children`` of each of its threads (proc(5)), or,
    on a kernel without that file, the processes whose parent (/proc/<pid>/stat field 4) is ``pid``."""
    out: list[int] = []
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return out
    try:
        for tid in tasks:
            with open(f"/proc/{pid}/task/{tid}/children", encoding="ascii") as f:
                out += [int(c) for c in f.read().split()]
    except FileNotFoundError:  # no CONFIG_PROC_CHILDREN (or the thread ended): the parents of every process
        out = [int(d) for d in os.listdir("/proc") if d.isdigit() and (_stat_fields(d) or ["", ""])[1] == str(pid)]
    return out


def running_for(driver: int) -> bool:
    """Whether a reaper for ``driver`` runs: a live child of ``driver`` whose command line runs this file for it
    (``python -S <this file> <driver> ...``, :func:`start`; an ended one that is not waited for yet, a zombie, has
    an empty command line)."""
    me = os.path.abspath(__file__).encode()
    for pid in _children(driver):
        argv = _cmdline(pid)
        if len(argv) >= 4 and argv[2] == me and argv[3] == str(driver).encode():
            return True
    return False


def _cmdline(pid: int, wait_s: float = 1.0) -> list[bytes]:
    """The command line of ``pid`` (/proc/<pid>/cmdline, split at NUL), ``[]`` when it is gone. A process that
    has just exec'd reads empty for a moment (seen right after ``subprocess.Popen`` returned): read again, up to
    ``wait_s``, unless it is a zombie (whose command line stays empty)."""
    end = time.monotonic() + wait_s
    while True:
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                raw = f.read()
        except OSError:
            return []
        fields = _stat_fields(pid)
        if raw or fields is None or fields[0] == "Z" or time.monotonic() >= end:
            return raw.split(b"\0")
        time.sleep(0.01)


def _watch(driver: int, period_s: float, grace_s: float) -> int:
    born = start_time(driver)
    if born is None:  # gone before this reaper looked: what it made and nobody maps is all there is to reap
        sweep_segments({driver})
        return 0
    me = os.getpid()
    seen: dict[int, int] = {}
    while start_time(driver) == born:
        try:
            for pid in descendants(driver):
                if pid != me and pid not in seen:
                    t = start_time(pid)
                    if t is not None:
                        seen[pid] = t
        except Exception:  # noqa: BLE001 - a reaper that dies reaps nothing: try again at the next period
            pass
        time.sleep(period_s)
    deadline = time.monotonic() + grace_s
    while time.monotonic() < deadline and any(start_time(p) == t for p, t in seen.items()):
        time.sleep(0.1)
    for pid, t in seen.items():
        if start_time(pid) == t:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
    sweep_segments(set(seen) | {driver})  # what a killed (or crashed) actor of the run left and nobody maps
    return 0


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a Ctrl-C meant for the run is not meant for its reaper
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("driver", type=int)
    ap.add_argument("period_s", type=float)
    ap.add_argument("grace_s", type=float)
    a = ap.parse_args()
    sys.exit(_watch(a.driver, a.period_s, a.grace_s))
