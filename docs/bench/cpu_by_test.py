"""A pytest plugin: the CPU each test costs the machine, its actors and subprocesses included, under xdist too.

A thread in each pytest process samples every 0.2 s the CPU time (utime + stime, ``/proc/<pid>/stat``) of every
process below it (the Ray session it started, that session's actors, the ``aerodaas`` subprocesses and their own
Ray) and adds what each used since its last sample to the test running then; a process first seen counts whole, one
that ended loses under 0.2 s. Written per pytest process as JSON (``{nodeid: {"tree", "own", "wall"}}``: CPU-s of the
tree, CPU-s of the pytest process itself, wall s) to ``$CPU_BY_TEST_OUT`` with the xdist worker's id before
``.json``::

    PYTHONPATH=docs/bench CPU_BY_TEST_OUT=/tmp/cpu.json python3 -m pytest -p cpu_by_test -n 4 --dist loadgroup \\
        -m "not slow" tests
    python3 docs/bench/cpu_by_test.py "/tmp/cpu.*.json"        # the costliest files and tests

Processes outside the tree (a daemon that detached, another pytest worker's) are not counted.
"""
import glob
import json
import os
import sys
import threading
import time

HZ = os.sysconf("SC_CLK_TCK")
CURRENT = ["<between tests>"]
RECORDS: dict[str, list[float]] = {}
LAST: dict[tuple[int, int], float] = {}
_LOCK = threading.RLock()
_STARTED: list[bool] = []


def _processes() -> dict[int, tuple[int, float, int]]:
    """pid → (parent pid, CPU-s so far, start time in clock ticks) of every process."""
    out = {}
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                f = open(f"/proc/{d}/stat").read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            out[int(d)] = (int(f[1]), (int(f[11]) + int(f[12])) / HZ, int(f[19]))
    return out


def _sample(root: int) -> None:
    """Add the CPU the tree below ``root`` used since the last sample to the current test."""
    procs = _processes()
    children: dict[int, list[int]] = {}
    for pid, (ppid, _, _) in procs.items():
        children.setdefault(ppid, []).append(pid)
    stack, used = [root], 0.0
    with _LOCK:
        while stack:
            pid = stack.pop()
            if pid in procs:
                key, cpu = (pid, procs[pid][2]), procs[pid][1]
                used += cpu - LAST.get(key, 0.0)
                LAST[key] = cpu
            stack.extend(children.get(pid, []))
        RECORDS.setdefault(CURRENT[0], [0.0, 0.0, 0.0])[0] += used


def _loop(root: int) -> None:
    while True:
        time.sleep(0.2)
        try:
            _sample(root)
        except Exception:  # noqa: BLE001 - a measurement: one bad sample must not stop the others
            pass


def _runs_tests(config) -> bool:
    """False in xdist's controller, which runs no test (every worker's tree is below it)."""
    return hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None)


def pytest_configure(config):
    if _runs_tests(config):
        threading.Thread(target=_loop, args=(os.getpid(),), daemon=True, name="cpu_by_test").start()


def _switch(to: str) -> None:
    """Charge what the tree used so far to the current test, then make ``to`` the current one."""
    with _LOCK:
        _sample(os.getpid())
        CURRENT[0] = to


def pytest_runtest_logstart(nodeid, location):
    if nodeid.startswith("<") or not _STARTED:
        return
    _switch(nodeid)
    RECORDS.setdefault(nodeid, [0.0, 0.0, 0.0])
    RECORDS[nodeid][1] -= time.process_time()
    RECORDS[nodeid][2] -= time.monotonic()


def pytest_runtest_logfinish(nodeid, location):
    if nodeid not in RECORDS or not _STARTED:
        return
    _switch("<between tests>")
    RECORDS[nodeid][1] += time.process_time()
    RECORDS[nodeid][2] += time.monotonic()


def pytest_sessionstart(session):
    if _runs_tests(session.config):
        _STARTED.append(True)


def pytest_sessionfinish(session):
    if not _STARTED:
        return
    out = os.environ.get("CPU_BY_TEST_OUT", "/tmp/cpu_by_test.json")
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    with open(f"{out.removesuffix('.json')}.{worker}.json", "w") as f:
        json.dump({k: {"tree": v[0], "own": v[1], "wall": v[2]} for k, v in RECORDS.items()}, f)


def report(paths: list[str], top: int = 30) -> None:
    """Print the total and the ``top`` costliest files and tests of the plugin's JSON files."""
    recs: dict[str, dict] = {}
    for p in paths:
        with open(p) as f:
            for k, r in json.load(f).items():  # "<between tests>" is in every file: added up
                acc = recs.setdefault(k, {"tree": 0.0, "own": 0.0, "wall": 0.0})
                for key in acc:
                    acc[key] += r[key]
    files: dict[str, list[float]] = {}
    for k, r in recs.items():
        acc = files.setdefault(k.split("::")[0], [0.0, 0.0, 0.0])
        for i, key in enumerate(("tree", "own", "wall")):
            acc[i] += r[key]
    print(f"{len(recs)} records, {sum(r['tree'] for r in recs.values()):.0f} CPU-s in all "
          f"({sum(r['own'] for r in recs.values()):.0f} in the pytest processes themselves)")
    print("CPU-s  pytest  wall  file")
    for name, (tree, own, wall) in sorted(files.items(), key=lambda x: -x[1][0])[:top]:
        print(f"{tree:6.1f} {own:6.1f} {wall:6.1f}  {name}")
    print("CPU-s  pytest  wall  test")
    for name, r in sorted(recs.items(), key=lambda x: -x[1]["tree"])[:top]:
        print(f"{r['tree']:6.1f} {r['own']:6.1f} {r['wall']:6.1f}  {name}")


if __name__ == "__main__":
    report([p for a in sys.argv[1:] for p in glob.glob(a)])
