"""A local Ray node start that timed out says why: which of its raylet and GCS still ran and the last lines of their
logs, read from the attempt's own session folder (never another process's), printed with the warning of each
attempt by a run's driver and by `aerodaas up`'s daemon. No Ray: session folders laid out as Ray 2.60 writes them
and stand-in processes named as Ray's are."""
from __future__ import annotations

import os
import shutil
import subprocess
import time
from pathlib import Path

import pytest

import aerodaas.runtime.ray_start as ray_start
from aerodaas.clusters import node_logs, persistent


def _session(temp_dir, pid: int, stamp: str, logs: dict[str, str], age_s: float = 0.0) -> str:
    path = temp_dir / f"session_2026-11-29_{stamp}_{pid}"
    (path / "logs").mkdir(parents=True)
    for name, text in logs.items():
        (path / "logs" / name).write_text(text)
    if age_s:
        t = time.time() - age_s
        os.utime(path, (t, t))
    return str(path)


def _named(tmp_path, name: str) -> subprocess.Popen:
    """A process whose /proc/<pid>/comm is ``name`` (its executable's file name), as Ray's raylet and GCS are."""
    exe = tmp_path / name
    shutil.copy(shutil.which("sleep"), exe)
    proc = subprocess.Popen([str(exe), "120"])
    for _ in range(600):  # until it has exec'd (a forked child still carries its parent's name)
        if Path(f"/proc/{proc.pid}/comm").read_text().strip() == name:
            return proc
        time.sleep(0.1)
    raise AssertionError(f"{name} never exec'd")


def test_the_report_reads_this_attempts_session_and_says_which_process_ran(tmp_path):
    temp = tmp_path / "ray"
    me = 4242
    lines = "".join(f"raylet line {i}\n" for i in range(100))
    _session(temp, me, "09-00-00_000001", {"raylet.err": "an older attempt's error\n"}, age_s=600)
    _session(temp, me + 1, "13-00-00_000003", {"raylet.err": "another driver's raylet\n"})
    since = time.time()
    ours = _session(temp, me, "13-00-00_000002", {"raylet.err": lines, "gcs_server.out": "\n\nGCS started\n",
                                                  "raylet.out": ""})
    gcs = _named(tmp_path, "gcs_server")
    try:
        report = node_logs.failed_start_report(str(temp), me, since, [gcs.pid], lines=5)
    finally:
        gcs.kill()
        gcs.wait(timeout=60)
    assert report.splitlines()[0] == "Ray node processes at the failure: raylet not running, gcs_server running"
    assert f"last lines of {ours}/logs/raylet.err:" in report
    assert [ln.strip() for ln in report.splitlines() if ln.strip().startswith("raylet line")] == \
        [f"raylet line {i}" for i in range(95, 100)]
    assert "GCS started" in report and "raylet.out" not in report  # an empty file is not listed
    assert "older attempt" not in report and "another driver" not in report


def test_a_missing_session_or_empty_logs_are_said_so(tmp_path):
    assert "no session folder of process 7 in" in node_logs.failed_start_report(str(tmp_path / "none"), 7, 0.0, [])
    empty = _session(tmp_path, 7, "13-00-00_000001", {})
    assert f"the node's log files in {empty}/logs are empty or missing" in \
        node_logs.failed_start_report(str(tmp_path), 7, 0.0, [])


def test_a_huge_log_is_read_only_at_its_end(tmp_path):
    _session(tmp_path, 7, "13-00-00_000001", {"raylet.out": "x" * 5_000_000 + "\nthe last line\n"})
    report = node_logs.failed_start_report(str(tmp_path), 7, 0.0, [], lines=2, max_bytes=1024)
    assert "the last line" in report and len(report) < 2_000


def test_a_drivers_timed_out_start_prints_the_report_with_each_attempt(tmp_path, monkeypatch, capsys):
    import ray

    temp = tmp_path / "ray"
    calls = []

    def timed_out_init(**kw):
        calls.append(kw["_temp_dir"])
        _session(temp, os.getpid(), f"13-00-0{len(calls)}_00000{len(calls)}",
                 {"raylet.err": f"raylet failure of attempt {len(calls)}\n"})
        raise Exception("The current node timed out during startup. This could happen because ...")

    monkeypatch.setattr(ray, "init", timed_out_init)
    # the real one would disconnect this pytest worker from its shared Ray session (other tests' runs)
    monkeypatch.setattr(ray, "shutdown", lambda: None)
    monkeypatch.setattr(ray_start, "ray_temp_dir", lambda: str(temp))
    monkeypatch.setattr(ray_start, "limit_malloc_arenas", lambda: False)
    monkeypatch.setattr(ray_start, "lean_worker_imports", lambda: False)
    monkeypatch.setattr(ray_start.reaper, "ensure_started", lambda: None)
    with pytest.raises(Exception, match="timed out during startup"):
        ray_start._start_local(dashboard=False)
    err = capsys.readouterr().err
    assert len(calls) == 3
    for attempt in (1, 2, 3):
        assert f"Ray's node start timed out (attempt {attempt} of 3)" in err
        assert f"raylet failure of attempt {attempt}" in err
    assert "raylet not running, gcs_server not running" in err


def test_the_daemons_timed_out_start_prints_the_report(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("RAY_TMPDIR", str(tmp_path))
    assert node_logs.default_temp_dir() == str(tmp_path / "ray")

    class TimedOut:
        def __init__(self, **kw):
            _session(tmp_path / "ray", os.getpid(), "13-00-00_000001", {"gcs_server.err": "GCS could not bind\n"})
            raise Exception("The current node timed out during startup.")

    monkeypatch.setattr(persistent, "HEAD_START_ATTEMPTS", 1)
    with pytest.raises(Exception, match="timed out during startup"):
        persistent._start_head(TimedOut, {})
    err = capsys.readouterr().err
    assert "aerodaas up: Ray's node start timed out (attempt 1 of 1)" in err and "GCS could not bind" in err
