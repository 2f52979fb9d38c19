"""The log monitor of a Ray that AeroDaaS starts (``aerodaas.clusters.log_monitor``): the log files of ended workers
are set aside, so its idle polls do not grow with every actor the node had, and every line an actor prints still
reaches the driver. Read from outside: the monitor's own command line names the logs folder, whose ``old``
sub-folder is where Ray's monitor moves the files of a worker it finds ended."""
from __future__ import annotations

import os
import re
import sys
import time
from pathlib import Path

import psutil

from aerodaas.clusters.log_monitor import MAX_OPEN_FILES


def _logs_dir() -> Path:
    """The logs folder of the Ray node this process started (its log monitor's ``--logs-dir``)."""
    for p in psutil.Process().children(recursive=True):
        try:
            cmd = p.cmdline()
        except psutil.Error:
            continue
        if any(a.endswith("log_monitor.py") for a in cmd):
            return Path(next(a.split("=", 1)[1] for a in cmd if a.startswith("--logs-dir=")))
    raise AssertionError("no log monitor among this process's descendants")


def _line(tag: str, i: int, stream: str) -> str:
    """The ``i``-th actor's line: told apart by letters, as Ray's console merges lines that differ only in numbers."""
    return f"talker-line {tag} {chr(ord('a') + i) * 3} {stream}"


def _talk(n: int, tag: str) -> list[int]:
    """Start ``n`` actors, each printing one line to stdout and one to stderr (:func:`_line`); end them; their
    pids."""
    import ray

    @ray.remote(num_cpus=0)
    class Talker:
        def talk(self, i: int) -> int:
            print(_line(tag, i, "out"), flush=True)
            print(_line(tag, i, "err"), file=sys.stderr, flush=True)
            return os.getpid()

    actors = [Talker.remote() for _ in range(n)]
    pids = ray.get([a.talk.remote(i) for i, a in enumerate(actors)])
    for a in actors:
        ray.kill(a)
    return pids


def test_ended_workers_logs_are_set_aside_and_every_line_reaches_the_driver(ray_session, capfd):
    """A first round of actors prints and ends; a second round opens more than ``MAX_OPEN_FILES`` files: the monitor
    then closes its files and moves the first round's to ``logs/old`` (with Ray's default of 200 open files it moves
    none). Every line of both rounds reaches the driver's console."""
    logs = _logs_dir()
    first = _talk(2, "first")
    second = _talk(MAX_OPEN_FILES // 2 + 1, "second")
    want = {_line(tag, i, s) for tag, n in (("first", len(first)), ("second", len(second)))
            for i in range(n) for s in ("out", "err")}
    seen: str = ""
    moved: set[int] = set()
    deadline = time.monotonic() + 60.0  # the monitor polls every 0.1-0.5 s; generous for a loaded machine
    while time.monotonic() < deadline:
        out, err = capfd.readouterr()
        seen += out + err
        old = logs / "old"
        names = [f.name for f in old.iterdir()] if old.is_dir() else []
        moved = {pid for pid in first if any(re.search(rf"-{pid}\.(out|err)$", n) for n in names)}
        if moved == set(first) and all(line in seen for line in want):
            break
        time.sleep(0.25)
    assert moved == set(first), f"the ended workers' files not set aside: {sorted(set(first) - moved)} in {logs}"
    missing = sorted(line for line in want if line not in seen)
    assert not missing, f"lines that did not reach the driver: {missing}"


def test_a_users_own_setting_is_kept_and_the_tuning_can_be_turned_off(monkeypatch):
    """A value the user set is left as it is (and reported as not in effect); ``AERODAAS_LEAN_LOG_MONITOR=0`` sets
    nothing; otherwise both of Ray's settings are in the environment the node processes inherit."""
    from aerodaas.clusters.log_monitor import SETTINGS, lean_log_monitor

    for k in SETTINGS:  # set then removed: the test's changes are undone after it, whatever the worker had
        monkeypatch.setenv(k, "")
        monkeypatch.delenv(k)
    monkeypatch.setenv("AERODAAS_LEAN_LOG_MONITOR", "0")
    assert lean_log_monitor() is False and not [k for k in SETTINGS if k in os.environ]
    monkeypatch.delenv("AERODAAS_LEAN_LOG_MONITOR")
    monkeypatch.setenv("RAY_LOG_MONITOR_MAX_OPEN_FILES", "500")
    assert lean_log_monitor() is False
    assert os.environ["RAY_LOG_MONITOR_MAX_OPEN_FILES"] == "500"
    assert os.environ["RAY_LOG_MONITOR_MANY_FILES_THRESHOLD"] == SETTINGS["RAY_LOG_MONITOR_MANY_FILES_THRESHOLD"]
    monkeypatch.delenv("RAY_LOG_MONITOR_MAX_OPEN_FILES")
    assert lean_log_monitor() is True and all(os.environ[k] == v for k, v in SETTINGS.items())
