"""A pytest plugin: the machine's busy CPU-s (``/proc/stat``: user, nice, system, irq, softirq) from each test's
setup to its teardown, one JSON line per test (``{"id", "cpu", "wall"}``) in ``$CPU_MACHINE_OUT`` (default
``/tmp/cpu_machine.<pid>.jsonl``). Meaningful on one pytest worker with nothing else running: then a test's figure is
everything it made the machine do (its Ray actors, emulators, subprocesses, and whatever the shared Ray session did
meanwhile)::

    PYTHONPATH=docs/bench python3 -m pytest -p cpu_machine_by_test -n 1 --dist loadgroup -m "not slow" tests
"""
import json
import os
import time

import pytest

_HZ = os.sysconf("SC_CLK_TCK")
_OUT = open(os.environ.get("CPU_MACHINE_OUT", f"/tmp/cpu_machine.{os.getpid()}.jsonl"), "a", encoding="utf-8")


def _busy_s() -> float:
    with open("/proc/stat", encoding="ascii") as f:
        v = [int(x) for x in f.readline().split()[1:]]
    return (v[0] + v[1] + v[2] + v[5] + v[6]) / _HZ


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    cpu, wall = _busy_s(), time.monotonic()
    yield
    _OUT.write(json.dumps({"id": item.nodeid, "cpu": _busy_s() - cpu, "wall": time.monotonic() - wall}) + "\n")
    _OUT.flush()
