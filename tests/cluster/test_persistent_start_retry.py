"""`aerodaas up`'s daemon starts its head node again when Ray's start times out on a loaded machine, after killing the
processes the failed attempt left, and gives up with Ray's error after the last attempt or at once on any other
error. No Ray: a stand-in for ``ray.cluster_utils.Cluster``."""
from __future__ import annotations

import subprocess
import sys

import pytest

from aerodaas.clusters import persistent


class _FlakyCluster:
    """Fails with Ray's startup-timeout message ``fails`` times, each time leaving a child process behind."""

    left: list[subprocess.Popen] = []
    calls = 0

    def __init__(self, *, initialize_head: bool, shutdown_at_exit: bool, head_node_args: dict, fails: int = 2,
                 message: str = "The current node timed out during startup.") -> None:
        type(self).calls += 1
        self.head_node_args = head_node_args
        if type(self).calls <= fails:
            type(self).left.append(subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"]))
            raise Exception(message)


def _cluster_type(fails: int, message: str = "The current node timed out during startup."):
    cls = type("Flaky", (_FlakyCluster,), {"left": [], "calls": 0})

    def make(**kw):
        return cls(fails=fails, message=message, **kw)
    make.cls = cls
    return make


def test_a_timed_out_start_is_retried_and_its_processes_killed():
    make = _cluster_type(fails=2)
    try:
        cluster = persistent._start_head(make, {"num_cpus": 1})
        assert cluster.head_node_args == {"num_cpus": 1} and make.cls.calls == 3
        assert all(p.wait(timeout=60) is not None for p in make.cls.left) and len(make.cls.left) == 2
    finally:
        for p in make.cls.left:
            p.kill()


def test_the_last_timeout_and_any_other_error_are_raised():
    make = _cluster_type(fails=persistent.HEAD_START_ATTEMPTS)
    with pytest.raises(Exception, match="timed out during startup"):
        persistent._start_head(make, {})
    assert make.cls.calls == persistent.HEAD_START_ATTEMPTS
    other = _cluster_type(fails=1, message="Failed to bind to 127.0.0.1:8265")
    with pytest.raises(Exception, match="Failed to bind"):
        persistent._start_head(other, {})
    assert other.cls.calls == 1
    for p in make.cls.left + other.cls.left:
        p.kill()
