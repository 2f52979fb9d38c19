"""Where a machine's CPU goes while something runs: every 0.5 s, each process's CPU time (utime + stime, /proc/<pid>/stat)
by kind (Ray's node processes, Ray workers by actor class, pytest workers, other Python commands), summed per kind
and written as JSON to the file given when this process gets SIGTERM. A process that lives under 0.5 s is missed and
the last half second of one that ends is lost, so the sum is a lower bound.

    python docs/bench/cpu_by_kind.py out.json & SAMPLER=$!; <the command>; kill $SAMPLER
"""
import os, sys, time, json, signal
HZ = os.sysconf("SC_CLK_TCK")
seen = {}
def kind(pid):
    try:
        cmd = open(f"/proc/{pid}/cmdline","rb").read().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return None
    if not cmd: return None
    if cmd.startswith("ray::"):
        w = cmd.split()[0].split(".")[0]
        return "ray-worker:" + (w.rsplit(":", 1)[-1] if ":" in w[5:] else w)
    if "default_worker.py" in cmd: return "ray-worker:unnamed"
    for k in ("gcs_server", "raylet", "dashboard_agent", "runtime_env_agent", "log_monitor", "monitor.py", "dashboard.py"):
        if k in cmd: return "ray:" + k
    if cmd.startswith("ray::"): return "ray-worker:" + cmd.split()[0].split(".")[0]
    if "default_worker.py" in cmd: return "ray-worker:idle"
    if "pytest" in cmd and "xdist" not in cmd and "-c" not in cmd: return "pytest"
    if "execnet" in cmd or "xdist" in cmd or ("-c" in cmd and "import sys;exec" in cmd): return "pytest-worker"
    if "aerodaas" in cmd.split()[0] or " -m aerodaas" in cmd or "/bin/aerodaas" in cmd: return "aerodaas-cli"
    if "sitl" in cmd.lower() or "arducopter" in cmd or "px4" in cmd: return "sitl"
    if "node" in cmd.split()[0]: return "node"
    if "python" in cmd.split()[0]: return "python:" + " ".join(cmd.split()[1:4])[:90]
    return "other:" + cmd.split()[0][-30:]
def snap():
    for d in os.listdir("/proc"):
        if not d.isdigit(): continue
        try:
            f = open(f"/proc/{d}/stat").read().rsplit(")",1)[1].split()
        except OSError: continue
        cpu = (int(f[11]) + int(f[12])) / HZ; st = f[19]
        key = (d, st)
        if key not in seen:
            k = kind(d)
            if k is None: continue
            seen[key] = [k, cpu]
        else:
            seen[key][1] = max(seen[key][1], cpu)
            if seen[key][0] in ("ray-worker:unnamed", "ray-worker:ray::IDLE"):
                k = kind(d)
                if k: seen[key][0] = k
def dump(*_):
    out = {}
    for (pid, st), (k, c) in seen.items():
        o = out.setdefault(k, [0, 0.0]); o[0] += 1; o[1] += c
    json.dump(dict(sorted(out.items(), key=lambda x: -x[1][1])), open(sys.argv[1], "w"), indent=0)
    sys.exit(0)
signal.signal(signal.SIGTERM, dump)
base = set()
while True:
    snap(); time.sleep(0.5)
