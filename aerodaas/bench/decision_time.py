"""Decision time of one analytics dispatcher's policy: p50/p99 of the CPU time a policy spends per dispatcher event.

The policy is driven by the deterministic harness (:mod:`aerodaas.bench.harness`) over one edge of the runtime
benchmark's trace (HEAVY, 3 drones per edge by default; any trace kind of :mod:`aerodaas.bench.traces`); every call
the dispatcher makes on an event (``submit`` on arrival, ``poll``, ``on_edge_done`` / ``on_cloud_done`` on completion, then
``next_edge_task``) is timed with :func:`time.perf_counter` (wall, ``decision_ms``) and :func:`time.thread_time`
(CPU of this thread, ``decision_cpu_ms``: what the policy costs, less sensitive to other processes on a loaded
machine), and the calls of one event are summed into one decision.
The ``cloud_admit`` probes (a dozen per cloud task, bisected into an admit-by time) are timed separately.

Run: ``python -m aerodaas.bench.decision_time --scheduler LAPLAN --trace realistic --out decision.json`` (the
trace's parameters are the ``--trace-*`` options of ``aerodaas bench schedulers``). The numbers are wall-clock on a
shared machine: run under ``nice`` and read them with the machine and the load average recorded beside them
(``machine``, ``load_average`` in the JSON). Everything that shapes the result is in the JSON: the trace's
parameters, the edge and cloud jitter, the scheduler's options and whether LAPLAN's planner ran compiled.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import asdict
from typing import Sequence

from aerodaas.bench.harness import Harness, fleet_tasks
from aerodaas.bench.machine import machine_info
from aerodaas.bench.options import LOADS
from aerodaas.bench.workload import default_workload_path, make_trace
from aerodaas.bench.schedulers_cli import scheduler_option, trace_options
from aerodaas.bench.schedulers_main import trace_spec
from aerodaas.bench.traces import TraceSpec
from aerodaas.schedulers import single_machine_jit
from aerodaas.schedulers.analytics_base import Workload, analytics_scheduler_class, make_analytics_scheduler
from aerodaas.schedulers.dispatch.emulation import Jitter

__all__ = ["measure", "main"]

_DECIDE = ("submit", "next_edge_task", "poll", "on_edge_done", "on_cloud_done", "on_cloud_availability")


def _pct(xs: Sequence[float], q: float) -> float:
    s = sorted(xs)
    return s[min(len(s) - 1, int(q * len(s)))] if s else float("nan")


def _policy(scheduler: str, w, options: dict):
    """``scheduler`` built for workload ``w`` with ``options``. Raises ValueError naming the option and the
    scheduler for an option it does not take (it would be ignored, yet recorded as applied), and for an unknown
    scheduler."""
    takes = analytics_scheduler_class(scheduler).options
    bad = [k for k in options if k not in takes]
    if bad:
        raise ValueError(f"--option {', '.join(bad)}: scheduler {scheduler} does not take "
                         f"{'it' if len(bad) == 1 else 'them'} (it takes: {', '.join(takes) or 'no option'})")
    return make_analytics_scheduler(scheduler, w, **{k: v for k, v in options.items() if v is not None})


def measure(scheduler: str = "LAPLAN", *, load: str = "HEAVY", drones_per_edge: int = 3, duration_s: float = 60.0,
            seed: int = 0, trace="realistic", cloud_sigma: float = 0.1, options: dict | None = None,
            edge_jitter: str = "lognormal:0.05") -> dict:
    """Decision times (ms) of ``scheduler`` on edge ``edge00`` of the benchmark trace: ``decision`` p50/p99/max/
    mean over dispatcher events, ``cloud_admit`` p50/p99 per probe, the event count and the utility (to check the
    timed run is the real one), beside what shaped them (machine, trace parameters, jitters, options, whether
    LAPLAN's planner ran compiled). ``trace``: a :class:`aerodaas.bench.traces.TraceSpec` or its kind (default
    parameters). Raises ValueError for an unknown scheduler, load or trace, a bad jitter, or an option the
    scheduler does not take."""
    if load not in LOADS:
        raise ValueError(f"load: choose from {list(LOADS)}, got {load!r}")
    w = Workload.from_file(default_workload_path(), load)
    spec = trace if isinstance(trace, TraceSpec) else TraceSpec.parse(trace)
    ej, cj = Jitter.parse(edge_jitter), Jitter("lognormal", cloud_sigma)
    pol = _policy(scheduler, w, dict(options or {}))
    per_edge = fleet_tasks(make_trace(w, drones_per_edge, duration_s, seed, drones_per_edge, 1.0, spec), w)
    events: list[float] = []
    probes: list[float] = []
    pending = [0.0]

    cpu_events: list[float] = []
    pending_cpu = [0.0]

    def timed(name, fn, sink):
        def wrapper(*a, **k):
            t0, c0 = time.perf_counter(), time.thread_time()
            try:
                return fn(*a, **k)
            finally:
                sink(time.perf_counter() - t0, time.thread_time() - c0)
        return wrapper

    def add(dt, dc):
        pending[0] += dt
        pending_cpu[0] += dc

    for name in _DECIDE:
        setattr(pol, name, timed(name, getattr(pol, name), add))
    pol.cloud_admit = timed("cloud_admit", pol.cloud_admit, lambda dt, dc: probes.append(dt * 1e3))

    class _Timed(Harness):
        def _kick(self):                       # called once after every event: closes the event's decision
            super()._kick()
            events.append(pending[0] * 1e3)
            cpu_events.append(pending_cpu[0] * 1e3)
            pending[0] = pending_cpu[0] = 0.0

    h = _Timed(pol, edge_jitter=ej, cloud_jitter=cj, seed=seed, edge_id="edge00")
    t0 = time.process_time()
    res = h.run(per_edge["edge00"])
    cpu = time.process_time() - t0
    return {"benchmark": "decision_time", "machine": machine_info(), "scheduler": scheduler, "load": load,
            "drones_per_edge": drones_per_edge, "duration_s": duration_s, "seed": seed, "trace": spec.label(),
            "trace_params": asdict(spec), "edge_jitter": str(ej), "cloud_sigma": cloud_sigma,
            "cloud_jitter": str(cj), "options": dict(options or {}),
            "laplan_planner": single_machine_jit.status(),
            "tasks": len(res.tasks), "utility": res.utility, "events": len(events),
            "decision_ms": {"p50": _pct(events, 0.5), "p99": _pct(events, 0.99), "max": max(events),
                            "mean": sum(events) / len(events)},
            "decision_cpu_ms": {"p50": _pct(cpu_events, 0.5), "p99": _pct(cpu_events, 0.99), "max": max(cpu_events),
                                "mean": sum(cpu_events) / len(cpu_events)},
            "cloud_admit_ms": {"p50": _pct(probes, 0.5), "p99": _pct(probes, 0.99), "calls": len(probes)},
            "cpu_s": cpu, "load_average": list(os.getloadavg()), "counters": dict(pol.counters),
            # the slow paths, never silent: plans solved by the pure-Python DP (numba missing) and plans
            # whose instance was cut to fit the compiled kernel's 64 live task groups (LAPLAN's counters)
            "slow_path": {k: pol.counters.get(k, 0) for k in ("plans", "plans_in_python", "plans_reduced")}}


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m aerodaas.bench.decision_time", description=__doc__.split("\n")[0])
    p.add_argument("--scheduler", default="LAPLAN")
    p.add_argument("--load", default="HEAVY")
    p.add_argument("--drones-per-edge", type=int, default=3)
    p.add_argument("--duration", type=float, default=60.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--option", type=scheduler_option, action="append", default=[], metavar="KEY=JSON",
                   help="scheduler option, e.g. replan_tolerance_ms=0; repeatable")
    p.add_argument("--out", help="also write the JSON here")
    trace_options(p, default="realistic")  # the same --trace and --trace-* options as `aerodaas bench schedulers`
    a = p.parse_args(argv)
    try:
        res = measure(a.scheduler, load=a.load, drones_per_edge=a.drones_per_edge, duration_s=a.duration,
                      seed=a.seed, trace=trace_spec(a), options=dict(a.option))
    except ValueError as e:
        print(f"decision_time: {e}", file=sys.stderr)
        return 2
    text = json.dumps(res, indent=1)
    print(text)
    if a.out:
        with open(a.out, "w") as f:
            f.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
