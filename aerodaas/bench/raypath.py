"""``aerodaas bench raypath``: where Ray's call path spends its time for one frame hop on one node.

One 1280×720×3 uint8 frame (2.76 MB) and a ``num_cpus=0`` actor in the local Ray that AeroDaaS starts (token auth
on, loopback only). Each step is timed ``--repeat`` times (after 20 unmeasured warm-ups), median and p99 in µs:

* ``put_frame`` — ``ray.put(frame)`` (serialise + copy into the shared-memory object store);
* ``call_ref_roundtrip`` — ``ray.get(actor.touch.remote(ref))`` with the put frame's ObjectRef as the argument:
  submit, schedule onto the actor, resolve and deserialise the argument (zero-copy: a read-only view of the store),
  run a method that reads one pixel, return a small result;
  split into ``call_ref_submit_to_start`` (driver submit -> method body starts; the actor's clock, same machine
  CLOCK_MONOTONIC) and ``call_ref_start_to_get`` (method body starts -> the driver's ``ray.get`` returns);
* ``put_plus_call_ref`` — put and call together, the hop a drone actor would make per frame;
* ``actor_get_zero_copy`` — inside the actor, ``ray.get`` of the frame's ref passed nested (not resolved by Ray):
  the zero-copy deserialisation alone;
* ``get_small_ready`` — ``ray.get`` of a small result that is already available;
* ``call_empty_roundtrip`` — a call with no arguments (the floor of any hop);
* ``call_small_inline_roundtrip`` — a call with a small message (a dict of a few numbers, inlined in the task);
* ``call_frame_by_value_roundtrip`` — the numpy array passed by value (Ray puts it into the store for the call).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Any

import numpy as np
import ray

from aerodaas.bench.machine import machine_info
from aerodaas.bench.output import emit_report
from aerodaas.runtime import ray_start


class _Probe:
    """The receiving actor; every method returns the monotonic time at which its body started."""

    def touch(self, frame: np.ndarray) -> float:
        t = time.monotonic()
        int(frame[0, 0, 0])
        return t

    def get_nested(self, refs: list) -> float:
        t0 = time.perf_counter()
        frame = ray.get(refs[0])
        int(frame[0, 0, 0])
        return (time.perf_counter() - t0) * 1e6

    def small(self, msg: Any = None) -> float:
        return time.monotonic()


def _stats(us: list[float]) -> dict:
    a = np.asarray(us, float)
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99)), "mean": float(a.mean()), "n": int(a.size)}


def measure(repeat: int = 300, width: int = 1280, height: int = 720, warmup: int = 20) -> dict[str, dict]:
    """Times each step (see the module docstring); Ray must be initialised. Returns ``{step: {median, p99, mean,
    n}}`` in µs."""
    frame = np.random.default_rng(0).integers(0, 255, (height, width, 3), dtype=np.uint8)
    actor = ray.remote(num_cpus=0)(_Probe).remote()
    ray.get(actor.small.remote())
    small_msg = {"vx": 0.5, "vy": -0.25, "vz": 0.0, "yaw_rate": 1.0, "seq": 7, "robot": "uav"}
    out: dict[str, list[float]] = {k: [] for k in (
        "put_frame", "call_ref_roundtrip", "call_ref_submit_to_start", "call_ref_start_to_get", "put_plus_call_ref",
        "actor_get_zero_copy", "get_small_ready", "call_empty_roundtrip", "call_small_inline_roundtrip",
        "call_frame_by_value_roundtrip")}
    for i in range(warmup + repeat):
        keep = i >= warmup
        t0 = time.monotonic()
        ref = ray.put(frame)
        t1 = time.monotonic()
        start = ray.get(actor.touch.remote(ref))
        t2 = time.monotonic()
        zc = ray.get(actor.get_nested.remote([ref]))
        del ref
        r = actor.small.remote()
        ray.wait([r])
        t3 = time.monotonic()
        ray.get(r)
        t4 = time.monotonic()
        ray.get(actor.small.remote())
        t5 = time.monotonic()
        ray.get(actor.small.remote(small_msg))
        t6 = time.monotonic()
        ray.get(actor.touch.remote(frame))
        t7 = time.monotonic()
        if keep:
            for k, v in (("put_frame", t1 - t0), ("call_ref_roundtrip", t2 - t1),
                         ("call_ref_submit_to_start", start - t1), ("call_ref_start_to_get", t2 - start),
                         ("put_plus_call_ref", t2 - t0), ("get_small_ready", t4 - t3),
                         ("call_empty_roundtrip", t5 - t4), ("call_small_inline_roundtrip", t6 - t5),
                         ("call_frame_by_value_roundtrip", t7 - t6)):
                out[k].append(v * 1e6)
            out["actor_get_zero_copy"].append(zc)
    ray.kill(actor)
    return {k: _stats(v) for k, v in out.items()}


def run_raypath(repeat: int = 300) -> dict:
    machine = machine_info()
    ray_start.ensure_ray()
    try:
        res = measure(repeat)
    finally:
        ray_start.shutdown_ray()

    return {"benchmark": "raypath", "machine": machine, "load_avg_1min_end": round(os.getloadavg()[0], 2),
            "frame_shape": [720, 1280, 3], "frame_bytes": 720 * 1280 * 3, "repeat": repeat, "results_us": res}


def main(a: argparse.Namespace) -> int:
    """``aerodaas bench raypath`` with the options of :mod:`aerodaas.bench.parsers`: checks them (exit 2 naming a bad
    one), runs the benchmark and prints its report; returns the exit code."""
    if a.repeat < 1:
        print(f"aerodaas bench raypath: --repeat must be >= 1, got {a.repeat}", file=sys.stderr)
        return 2
    report = run_raypath(a.repeat)
    for k, v in report["results_us"].items():
        print(f"raypath {k:32s} median {v['median']:9.1f} µs  p99 {v['p99']:9.1f} µs", file=sys.stderr)

    emit_report(report, a.out, a.json)
    return 0
