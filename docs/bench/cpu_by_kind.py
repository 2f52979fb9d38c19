"""Where a machine's CPU goes while something runs: every 0.5 s, each process's CPU time (utime + stime, /proc/<pid>/stat)
by kind (Ray's node processes, Ray workers by actor class, pytest workers, other Python commands), summed per kind
and written as JSON (``{kind: [processes, CPU-s]}``, costliest first) to the file given when this process gets
SIGTERM. Only what was used while it ran counts: a process already running at the first sample counts from there.
A process that lives under 0.5 s is missed and the last half second of one that ends is lost, so the sum is a lower
bound.

    python docs/bench/cpu_by_kind.py out.json & SAMPLER=$!; <the command>; kill $SAMPLER

A process's kind is read from the first word of its command line (the binary, the script Python runs, or the
title Ray gives a worker: ``ray::DroneActor.run``), never from its arguments: a Ray worker names the raylet's socket
and the dashboard agent the raylet's and its log file's among theirs.
"""
import json
import os
import signal
import sys
import time

HZ = os.sysconf("SC_CLK_TCK")
#: a Python script of Ray's node -> its kind
RAY_SCRIPTS = {"agent.py": "ray:dashboard_agent", "log_monitor.py": "ray:log_monitor", "monitor.py": "ray:monitor",
               "dashboard.py": "ray:dashboard", "main.py": "ray:runtime_env_agent",
               "default_worker.py": "ray-worker:starting"}
#: a title Ray gives one of its node's Python processes -> its kind
RAY_TITLES = {"DashboardAgent": "ray:dashboard_agent", "RuntimeEnvAgent": "ray:runtime_env_agent",
              "IDLE": "ray-worker:idle"}
#: a command (its binary, its script or ``-m`` module) -> its kind
COMMANDS = {"pytest": "pytest", "aerodaas": "aerodaas-cli", "aerodaas.cli": "aerodaas-cli"}
#: (pid, start time) -> [kind, CPU-s at the first sample, CPU-s at the last]
seen: dict = {}


def _script(argv: list) -> str:
    """The script or module a Python command line runs ('-c' for inline code), '' for none."""
    rest = argv[1:]
    while rest and rest[0].startswith("-") and rest[0] not in ("-c", "-m"):
        rest = rest[1:]
    if not rest:
        return ""
    return rest[0] if rest[0] == "-c" else (f"-m {rest[1]}" if rest[0] == "-m" and len(rest) > 1 else rest[0])


def kind(pid: str):
    """The kind of process ``pid``, None when it is gone or has no command line (a kernel thread)."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            argv = f.read().replace(b"\0", b" ").decode(errors="replace").split()
    except OSError:
        return None
    if not argv:
        return None
    first = argv[0]
    if first.startswith("ray::"):
        title = first[5:].split(".")[0].rsplit(":", 1)[-1]
        return RAY_TITLES.get(title, "ray-worker:" + title)
    name = os.path.basename(first)
    if name in ("gcs_server", "raylet"):
        return "ray:" + name
    if name.startswith("python"):
        script = _script(argv)
        if "/ray/" in script and os.path.basename(script) in RAY_SCRIPTS:
            return RAY_SCRIPTS[os.path.basename(script)]
        if script == "-c" and "import sys;exec(eval(sys.stdin.readline()))" in " ".join(argv):
            return "pytest-worker"
        name = os.path.basename(script.removeprefix("-m "))
        if name in COMMANDS:
            return COMMANDS[name]
        return "python:" + (script if script != "-c" else " ".join(argv[1:4]))[-60:]
    return COMMANDS.get(name, "other:" + name[-30:])


def snap() -> None:
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        cpu = (int(fields[11]) + int(fields[12])) / HZ
        key = (d, fields[19])
        if key not in seen:
            k = kind(d)
            if k is None:
                continue
            seen[key] = [k, cpu if FIRST else 0.0, cpu]
        else:
            seen[key][2] = max(seen[key][2], cpu)
            if seen[key][0] in ("ray-worker:starting", "ray-worker:idle"):  # an actor took the worker since
                seen[key][0] = kind(d) or seen[key][0]


def dump(*_) -> None:
    out: dict = {}
    for k, first, last in seen.values():
        if last > first:
            o = out.setdefault(k, [0, 0.0])
            o[0] += 1
            o[1] = round(o[1] + last - first, 2)
    with open(sys.argv[1], "w") as f:
        json.dump(dict(sorted(out.items(), key=lambda x: -x[1][1])), f, indent=0)
    sys.exit(0)


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, dump)
    FIRST = True
    snap()
    FIRST = False
    while True:
        time.sleep(0.5)
        snap()
