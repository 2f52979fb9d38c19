"""A local Ray start that failed (the raylet missed Ray's 30 s registration on a loaded machine) leaves no process
behind when ``aerodaas.runtime.ray_start`` tries again (``aerodaas.clusters.reaper.kill_started_since``): the retry kills this driver's descendants that the failed
attempt started in its Ray temp directory, and nothing else. No Ray: stand-in processes."""
from __future__ import annotations

import os
import subprocess
import sys

import psutil

from aerodaas.clusters import reaper


def _sleeper(tag: str) -> subprocess.Popen:
    # a process whose command line names `tag`, as Ray's GCS, raylet and dashboard name their temp directory
    return subprocess.Popen([sys.executable, "-c", "import time, sys; time.sleep(120)", f"--temp-dir={tag}"])


def test_a_failed_start_leaves_no_process_in_its_temp_dir_and_spares_the_rest(tmp_path):
    temp_dir = str(tmp_path / "ray")
    older = _sleeper(temp_dir)  # there before the attempt: not the attempt's
    before = set(reaper.descendants(os.getpid()))
    started = _sleeper(temp_dir)  # started by the attempt, in its temp dir
    other = _sleeper(str(tmp_path / "elsewhere"))  # started meanwhile, not Ray's of this driver
    try:
        reaper.kill_started_since(before, temp_dir)
        assert started.wait(timeout=60) is not None
        assert older.poll() is None and other.poll() is None
        assert psutil.pid_exists(older.pid) and psutil.pid_exists(other.pid)
    finally:
        for p in (older, started, other):
            p.kill()
            p.wait(timeout=60)
