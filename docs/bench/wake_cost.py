"""What one wake of a sleeping Python thread costs this machine: threads that only sleep, each at its own period
(5, 10, 50 and 100 ms) for the same span, their own CPU time (``time.thread_time``, the kernel's per-thread
count) and their wakes (voluntary context switches, ``/proc/self/task/<tid>/status``), side by side in one run::

    python3 docs/bench/wake_cost.py            # 20 s; prints one row per period and CPU-us per wake

A drone actor's threads that only hand work on (the clock between its due steps, the pool threads between frames,
Ray's main thread between its 10 ms signal checks) pay about this per wake on top of the work itself.
"""
import sys
import threading
import time

SPAN_S = float(sys.argv[1]) if len(sys.argv) > 1 else 20.0
PERIODS_MS = (5, 10, 50, 100)


def wakes(tid: int) -> int:
    with open(f"/proc/self/task/{tid}/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("voluntary_ctxt_switches:"))


def sleeper(period_s: float, out: dict) -> None:
    tid = threading.get_native_id()
    w0, c0 = wakes(tid), time.thread_time()
    for _ in range(int(SPAN_S / period_s)):
        time.sleep(period_s)
    out[period_s] = (time.thread_time() - c0, wakes(tid) - w0)


def main() -> None:
    out: dict = {}
    threads = [threading.Thread(target=sleeper, args=(p / 1000, out)) for p in PERIODS_MS]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    print(f"{'period ms':>9} {'wakes':>6} {'CPU s':>7} {'CPU s per s':>11} {'CPU us per wake':>15}")
    for p in PERIODS_MS:
        cpu, n = out[p / 1000]
        print(f"{p:9d} {n:6d} {cpu:7.3f} {cpu / SPAN_S:11.4f} {1e6 * cpu / max(n, 1):15.1f}")


if __name__ == "__main__":
    main()
