"""A pytest plugin: the machine's busy CPU-s (``/proc/stat``: user, nice, system, irq, softirq) from each test's
setup to its teardown, one JSON line per test (``{"id", "cpu", "wall"}``) appended to ``$CPU_MACHINE_OUT`` (default
``/tmp/cpu_machine.<pid>.jsonl``, the file opened at the first test). Meaningful on one pytest worker with nothing
else running: a test's figure is then everything it made the machine do (its Ray actors, emulators, subprocesses,
and whatever the shared Ray session did meanwhile). Run as a script, it sums the files by area (the folder under
``tests/``) and lists the costliest tests::

    PYTHONPATH=docs/bench python3 -m pytest -p cpu_machine_by_test -n 1 --dist loadgroup -m "not slow" tests
    python3 docs/bench/cpu_machine_by_test.py "/tmp/cpu_machine.*.jsonl"
"""
import collections
import glob
import json
import os
import sys
import time

import pytest

_HZ = os.sysconf("SC_CLK_TCK")
_OUT: list = []


def _busy_s() -> float:
    with open("/proc/stat", encoding="ascii") as f:
        v = [int(x) for x in f.readline().split()[1:]]
    return (v[0] + v[1] + v[2] + v[5] + v[6]) / _HZ


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    cpu, wall = _busy_s(), time.monotonic()
    yield
    if not _OUT:
        _OUT.append(open(os.environ.get("CPU_MACHINE_OUT", f"/tmp/cpu_machine.{os.getpid()}.jsonl"), "a",
                         encoding="utf-8"))
    _OUT[0].write(json.dumps({"id": item.nodeid, "cpu": _busy_s() - cpu, "wall": time.monotonic() - wall}) + "\n")
    _OUT[0].flush()


def main(pattern: str, top: int = 25) -> None:
    """Print the CPU-s and wall s of every file matching ``pattern``: in all, by area, and the ``top`` tests."""
    rows = [json.loads(line) for path in glob.glob(pattern) for line in open(path, encoding="utf-8")]
    cpu, wall = sum(r["cpu"] for r in rows), sum(r["wall"] for r in rows)
    print(f"{len(rows)} tests: {cpu:.0f} CPU-s, walls summed {wall:.0f} s")
    areas: collections.Counter = collections.Counter()
    for r in rows:
        parts = r["id"].split("::")[0].split("/")
        areas[parts[1] if len(parts) > 2 else parts[0]] += r["cpu"]
    print("by area (CPU-s): " + ", ".join(f"{a} {c:.0f}" for a, c in areas.most_common()))
    for r in sorted(rows, key=lambda r: -r["cpu"])[:top]:
        print(f"{r['cpu']:7.1f} CPU-s {r['wall']:7.1f} s  {r['id'].split('@')[0]}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "/tmp/cpu_machine.*.jsonl")
