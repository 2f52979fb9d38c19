"""The log monitor of a Ray that AeroDaaS starts (``aerodaas.clusters.log_monitor``): it runs with the settings, read
from outside (the monitor process's own environment, as the kernel holds it), and every line an actor prints still
reaches the driver, also from actors that end at once."""
from __future__ import annotations

import os
import sys
import time

import psutil

from aerodaas.clusters.log_monitor import SETTINGS


def _log_monitor() -> psutil.Process:
    """The log monitor of the Ray node this process started."""
    for p in psutil.Process().children(recursive=True):
        try:
            if any(a.endswith("log_monitor.py") for a in p.cmdline()):
                return p
        except psutil.Error:
            continue
    raise AssertionError("no log monitor among this process's descendants")


def _line(tag: str, i: int, stream: str) -> str:
    """The ``i``-th actor's line: told apart by letters, as Ray's console merges lines that differ only in numbers."""
    return f"talker-line {tag} {chr(ord('a') + i) * 3} {stream}"


def _talk(n: int, tag: str) -> None:
    """Start ``n`` actors, each printing one line to stdout and one to stderr (:func:`_line`); end them at once."""
    import ray

    @ray.remote(num_cpus=0)
    class Talker:
        def talk(self, i: int) -> int:
            print(_line(tag, i, "out"), flush=True)
            print(_line(tag, i, "err"), file=sys.stderr, flush=True)
            return os.getpid()

    actors = [Talker.remote() for _ in range(n)]
    ray.get([a.talk.remote(i) for i, a in enumerate(actors)])
    for a in actors:
        ray.kill(a)


def test_the_log_monitor_runs_with_the_settings_and_every_line_reaches_the_driver(ray_session, capfd):
    """The shared session's log monitor holds :data:`SETTINGS` in its environment (without them it lists the logs
    folder at every 0.1 s poll); the lines of actors that print and end at once all reach the driver's console."""
    env = _log_monitor().environ()
    assert {k: env.get(k) for k in SETTINGS} == SETTINGS
    _talk(3, "ended")
    want = {_line("ended", i, s) for i in range(3) for s in ("out", "err")}
    seen = ""
    deadline = time.monotonic() + 30.0  # the monitor lists the folder every 0.5 s: generous for a loaded machine
    while time.monotonic() < deadline and not all(line in seen for line in want):
        out, err = capfd.readouterr()
        seen += out + err
        time.sleep(0.25)
    missing = sorted(line for line in want if line not in seen)
    assert not missing, f"lines that did not reach the driver: {missing}"


def test_a_users_own_setting_is_kept_and_the_setting_can_be_turned_off(monkeypatch):
    """A value the user set is left as it is (and reported as not in effect); ``AERODAAS_LEAN_LOG_MONITOR=0`` sets
    nothing; otherwise every one of :data:`SETTINGS` is in the environment the node processes inherit."""
    from aerodaas.clusters.log_monitor import lean_log_monitor

    for k in SETTINGS:  # set then removed: the test's changes are undone after it, whatever the worker had
        monkeypatch.setenv(k, "")
        monkeypatch.delenv(k)
    monkeypatch.setenv("AERODAAS_LEAN_LOG_MONITOR", "0")
    assert lean_log_monitor() is False and not [k for k in SETTINGS if k in os.environ]
    monkeypatch.delenv("AERODAAS_LEAN_LOG_MONITOR")
    for k in SETTINGS:
        monkeypatch.setenv(k, "500")
        assert lean_log_monitor() is False and os.environ[k] == "500"
        monkeypatch.delenv(k)
    assert lean_log_monitor() is True and all(os.environ[k] == v for k, v in SETTINGS.items())
