"""The idle CPU of Ray's log monitor after N actors came and went, each printing one line: one local Ray node,
the monitor's CPU over 30 s when fresh and again after the actors ended (CPU-s a minute), appended as one JSON line
to ``log_monitor_idle.jsonl``. Settings ``VAR=VALUE`` go into the environment before Ray starts (as
``aerodaas.clusters.log_monitor`` does)::

    python3 docs/bench/log_monitor_idle.py 60                                   # Ray's defaults
    python3 docs/bench/log_monitor_idle.py 60 RAY_LOG_MONITOR_MANY_FILES_THRESHOLD=0 RAY_LOG_MONITOR_MAX_OPEN_FILES=16
"""
import json
import os
import sys
import time

for kv in sys.argv[2:]:
    k, v = kv.split("=", 1)
    os.environ[k] = v
import psutil  # noqa: E402
import ray  # noqa: E402

N = int(sys.argv[1])
ray.init(address="local", num_cpus=2, include_dashboard=False, logging_level="ERROR")
monitor = next(p for p in psutil.Process().children(recursive=True) if "log_monitor" in " ".join(p.cmdline()))


@ray.remote(num_cpus=0)
class Talker:
    def hello(self) -> int:
        print("hello from an actor")
        return os.getpid()


def idle_cpu_per_minute(seconds: float = 30.0) -> float:
    c0 = sum(monitor.cpu_times()[:2])
    time.sleep(seconds)
    return (sum(monitor.cpu_times()[:2]) - c0) * 60.0 / seconds


fresh = idle_cpu_per_minute()
for _ in range(N):
    a = Talker.remote()
    ray.get(a.hello.remote())
    ray.kill(a)
after = idle_cpu_per_minute()
with open("log_monitor_idle.jsonl", "a") as f:
    f.write(json.dumps({"settings": sys.argv[2:], "actors": N, "fresh": round(fresh, 3), "after": round(after, 3)})
            + "\n")
