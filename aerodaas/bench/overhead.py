"""``aerodaas bench overhead``: per-frame framework overhead of the analytics-driven control path, next to its peers.

The path: camera -> detector analytics -> follow analytics -> trajectory scheduler -> drone command (the velocity
setpoint reaching the vehicle backend), at 30 FPS, for each resolution, with the detector replaced by a
fixed-cost stub (``--stub-ms``; it sleeps like an accelerator that releases the CPU, and reports one box) and with
the real YOLOX-Nano (needs the model and the imagery, from ``$AERODAAS_MODEL_DIR``/``$AERODAAS_DATA_DIR``).

Framework overhead = end-to-end latency − inference − post-processing (the AeroDaaS paper's definition, §8.3.1),
per frame whose command reached the drone; end-to-end runs from the moment the frame is ready (rendered) to the
moment the command was applied. Four pipelines do the same work (:mod:`aerodaas.bench.pipeline`) on the same
frames, in one invocation, **interleaved**: round-robin windows of ``--window`` seconds (the order rotated each
round) until each has had ``--duration`` seconds, so a drift in the machine's load hits all of them alike:

* ``framework`` — the AeroDaaS runtime in each ``--layout``: ``colocated`` (detector and follow deployed with
  ``colocate=True``: everything runs in the drone actor, zero actor hops), ``actors`` (the detector in its own
  analytics actor on the same node, reached through the run's same-node channel — the frame copied once into a
  shared-memory slot, the message and the detections coming back on a Unix socket, :mod:`aerodaas.actors.data.channel`
  — to the follow controller colocated in the drone actor) and ``actors-ray`` (the same actors with
  ``same_node_transport: ray``: the frame ``ray.put`` once and an actor call per frame, the detections in the
  call's reply) and, with ``--lockstep``, ``actors+lockstep`` (the ``actors`` layout under the lock-step clock the
  shipped apps use: the same channel, the clock waiting for each frame's cascade, nothing dropped); one short
  mission per window (its take-off is not measured), optionally recorded (``--record``: then an unrecorded copy joins the rotation,
  ``framework_unrecorded_overhead_ms``, so the recording's cost shows);
* ``bare_loop`` — one process, plain function calls: the floor;
* ``naive_ray`` — one Ray actor per component, ``ray.put`` + actor call per hop (:mod:`.peers_naive_ray`);
* ``dora_rs`` — one dora-rs 1.1 node process per component, shared memory (:mod:`.peers_dora`; the optional
  ``bench`` extra; reported as unavailable, with the reason, when it is not installed);
* ``dora_rs_grouped`` — dora-rs grouped like the ``actors`` layout: camera, follow, scheduler and drone in one
  node process, the detector in another (2 crossings per frame, as ours), the same-shape peer.

The *honest tail* (stub only): end-to-end plus capture dispatch (camera tick -> render start) minus the stub's
*nominal* time, so the stub's sleep overshoot and every stall count (the paper's definition subtracts the measured
inference window, which hides them).
"""
from __future__ import annotations

import argparse
import math
import os
import shutil
import sys
import tempfile
import time
from typing import Any

import numpy as np

from aerodaas.analytics.core import FollowAnalytics
from aerodaas.app.api import Environment
from aerodaas.bench.machine import machine_info
from aerodaas.bench.options import LAYOUTS, LOCKSTEP
from aerodaas.bench.output import emit_report
from aerodaas.bench.peers_dora import DoraPipeline, unavailable_reason
from aerodaas.bench.peers_naive_ray import NaiveRayPipeline
from aerodaas.bench.pipeline import (FPS, CameraStage, CommandStage, DetectStage, DroneStage, FollowStage, Pacer, mp,
                                     overheads, parsed_config, summary)
from aerodaas.bench.pipeline import HOVER_M, make_detector
from aerodaas.bench.progress import bench_progress
from aerodaas.model.types import PriorityQueue
from aerodaas.perception.model_files import ModelNotFoundError, resolve_model
from aerodaas.runtime import ray_start
from aerodaas.runtime.options import RunOptions
from aerodaas.schedulers import TrajectoryScheduler

RESOLUTIONS = ((1280, 720), (640, 480))
NOT_MEASURED = "not flown in this invocation"
PEERS = ("bare_loop", "naive_ray", "dora_rs", "dora_rs_grouped")


class FrameworkWindows:
    """The AeroDaaS runtime in ``layout`` (see the module docstring): each :meth:`window` flies one mission of
    ``seconds`` after take-off (a climb at 4 m/s to the hover altitude) and ``settle_s`` more seconds, in the current
    Ray (the run's actors are started per mission), recorded to a temporary MCAP when ``record_dir`` is set. Returns
    the scheduler's latency records of applied commands plus the camera's dispatch figures."""

    name = "framework"

    def __init__(self, width: int, height: int, kind: str, stub_ms: float, record_dir: str | None,
                 layout: str = "colocated", settle_s: float = 4.0) -> None:
        self.args, self.record_dir, self.layout = (width, height, kind, stub_ms), record_dir, layout
        self.settle_s = settle_s
        self.n, self.info = 0, {"frames_captured": 0, "frames_dropped_busy_detector": 0, "host_errors": 0,
                                "dispatch": [], "recording_bytes": 0, "transports": set()}

    def window(self, seconds: float) -> list[dict]:
        width, height, kind, stub_ms = self.args
        env = Environment(parsed_config(width, height, kind))
        layout, lockstep = self.layout.removesuffix(LOCKSTEP), self.layout.endswith(LOCKSTEP)
        env.cfg.same_node_transport = "ray" if layout == "actors-ray" else "channel"
        env.cfg.simulation.lockstep = lockstep  # the clock waits for each frame's cascade (the shipped apps' mode)
        drone = env.get_robot_by_id("uav")
        edge = env.get_compute_resource_by_id("edge")
        sched = TrajectoryScheduler(env)
        det = make_detector(kind, stub_ms)
        det.deploy(edge, colocate=layout == "colocated")
        follow = FollowAnalytics(target_classes=["car", "truck", "bus"], confirm_hits=1, lost_after=1e9)
        follow.deploy(edge, colocate=True)
        sched.add_navigation(PriorityQueue(follow.analyse(det.analyse(drone.get_sensor_by_id("cam").get_data_stream())),
                                           priority=1))
        self.n += 1
        rec = os.path.join(self.record_dir, f"w{self.n}.mcap") if self.record_dir else None
        res = drone.start_mission(timeout=seconds + HOVER_M / 4.0 + self.settle_s,  # climb at 4 m/s, then settle
                                  options=RunOptions(progress=False, record=rec))
        cam = res.stats["uav"]["cameras"]["cam"]
        i = self.info
        i["frames_captured"] += cam.get("frames", 0)
        i["frames_dropped_busy_detector"] += res.stats["uav"]["analytics"][0].get("dropped", 0)
        i["host_errors"] += sum(h.get("error_count", 0) for h in res.stats.get("_hosts", {}).values())
        i["dispatch"].append((cam.get("dispatch_ms_median"), cam.get("dispatch_ms_p99")))
        i["transports"].update(o.get("transport") for o in cam.get("outlets", []))  # how frames left the drone
        if rec and os.path.exists(rec):
            i["recording_bytes"] += os.path.getsize(rec)
            os.remove(rec)
        recs = [r for r in res.stats["uav"]["scheduler"].get("latency_records", []) if r["applied"]]
        t_end = max((r["t"] for r in recs), default=0.0)
        return [r for r in recs if r["t"] > t_end - seconds]  # the window: the mission's last `seconds` of flight

    def report(self, recs: list[dict], kind: str, stub_ms: float) -> dict:
        i = self.info
        disp = [d for d in i["dispatch"] if d[0] is not None]
        d_med = float(np.median([d[0] for d in disp])) if disp else 0.0
        d_p99 = max((d[1] for d in disp), default=0.0)
        out = {"frames_captured": i["frames_captured"], "frames_dropped_busy_detector": i["frames_dropped_busy_detector"],
               "commands_applied": len(recs), "host_errors": i["host_errors"], "missions": self.n,
               "e2e_ms": summary([r["e2e_ms"] for r in recs]), "inference_ms": summary([r["inference_ms"] for r in recs]),
               "post_ms": summary([r["post_ms"] for r in recs]),
               "framework_overhead_ms": summary([r["overhead_ms"] for r in recs]),
               # the actors layout's hop, where its time goes: ray.put of the frame, the actor call (submit ->
               # the analytics actor's deliver starting), the zero-copy get, the reply back to the drone actor
               "hop_ms": {k: summary([r[k] for r in recs if k in r]) for k in ("put_ms", "call_ms", "get_ms",
                                                                                 "reply_ms")
                          if any(k in r for r in recs)},
               # from the camera's clock tick to its render starting on the host's thread pool (per window median
               # and p99 from the camera's stats: the runtime does not pair it with each frame's latency record)
               "capture_dispatch_ms": {"median": d_med, "p99": d_p99},
               "layout": self.layout, "lockstep": self.layout.endswith(LOCKSTEP),
               "recorded": self.record_dir is not None,
               # how the frames left the drone actor: [] (colocated), ["channel"] or ["ray"]
               "frame_transport": sorted(t for t in i["transports"] if t),
               "recording_bytes": i["recording_bytes"],
               "honest_overhead_ms": None}
        if kind == "stub" and recs:
            # frame by frame: end-to-end + that frame's capture dispatch (clock tick -> render start) − nominal
            out["honest_overhead_ms"] = {**summary([r["e2e_ms"] + r.get("dispatch_ms", 0.0) - stub_ms
                                                    for r in recs]),
                                         "dispatch": "per frame (each frame's own capture dispatch)"}
        return out


class BareLoop:
    """The same work in this process with plain function calls, paced at 30 FPS (frames that would start late are
    skipped, as a camera would); the camera renders at the backend's live position."""

    name = "bare_loop"

    def __init__(self, width: int, height: int, kind: str, stub_ms: float) -> None:
        rc = parsed_config(width, height, kind).robots[0]
        self.cam, self.det, self.follow = CameraStage(width, height, kind), DetectStage(kind, stub_ms), FollowStage()
        self.cmd, self.drone = CommandStage(rc), DroneStage(rc)
        self.t0 = time.monotonic()

    def window(self, seconds: float) -> list[dict]:
        rows, pacer = [], Pacer()
        start = time.monotonic()
        while time.monotonic() - start < seconds:
            tick = pacer.wait()
            t_start = time.monotonic()
            self.drone.step(pacer.period)
            frame, meta = self.cam.capture(self.drone.position, float(self.drone.backend.state().yaw), t_start - self.t0)
            ready = time.monotonic()
            dets, inf, post = self.det(frame, meta)
            nav, f_ms = self.follow(dets, meta)
            if nav is None:
                continue
            item = self.cmd(nav, self.drone.position, meta.capture_time)
            if item is None:
                continue
            self.drone.apply(item)
            rows.append({"tick": tick, "start": t_start, "ready": ready, "applied": time.monotonic(),
                         "inference_ms": inf, "post_ms": post + f_ms})
        return rows

    def close(self) -> None:
        pass


def _peer(name: str, width: int, height: int, kind: str, stub_ms: float) -> tuple[Any, str | None]:
    """(the pipeline, None) or (None, why it could not be started)."""
    try:
        if name == "bare_loop":
            return BareLoop(width, height, kind, stub_ms), None
        if name == "naive_ray":
            return NaiveRayPipeline(width, height, kind, stub_ms), None

        reason = unavailable_reason()
        shape = "grouped" if name == "dora_rs_grouped" else "per_component"
        return (None, reason) if reason else (DoraPipeline(width, height, kind, stub_ms, shape=shape), None)
    except Exception as e:  # a peer that cannot start is reported as such, never as a number
        return None, f"{type(e).__name__}: {e}"


def interleaved(width: int, height: int, kind: str, duration_s: float, window_s: float, stub_ms: float,
                record_dir: str | None, loads: list[float], layouts: tuple[str, ...] = ("colocated",),
                on_round: Any = None, settle_s: float = 4.0) -> dict:
    """Every pipeline for ``duration_s`` seconds in round-robin windows of ``window_s`` (order rotated each round,
    ``on_round()`` called after each round: the progress bar;
    one unmeasured warm-up window first for the peers). Returns ``{name: report}``; an unavailable pipeline's report,
    or a peer's that failed during the run (its windows are then discarded), is ``{"available": False, "reason":
    ...}``; the framework failing raises. When
    recording (``record_dir``), an unrecorded AeroDaaS runner joins the rotation (``framework_unrecorded``), so the
    recording's cost shows side by side. The runtime is flown in each of ``layouts`` (``framework:<layout>``), each
    mission ``settle_s`` seconds at its altitude before its window (:class:`FrameworkWindows`)."""
    runners: dict[str, Any] = {}
    for layout in layouts:
        runners[f"framework:{layout}"] = FrameworkWindows(width, height, kind, stub_ms, record_dir, layout, settle_s)
        if record_dir:
            runners[f"framework_unrecorded:{layout}"] = FrameworkWindows(width, height, kind, stub_ms, None, layout,
                                                                         settle_s)
    missing: dict[str, str] = {}
    failed: dict[str, str] = {}
    try:
        for name in PEERS:
            p, why = _peer(name, width, height, kind, stub_ms)
            if p is None:
                missing[name] = why or "unavailable"
                continue
            runners[name] = p
            try:
                p.window(min(1.0, window_s))  # warm-up: first frames through fresh processes
            except Exception as e:  # noqa: BLE001 - as a failure in a round (below)
                failed[name] = f"failed in its warm-up: {type(e).__name__}: {str(e)[-300:]}"
        rows: dict[str, list] = {n: [] for n in runners}
        order = list(runners)
        rounds = max(1, math.ceil(duration_s / window_s))
        for k in range(rounds):
            for name in order[k % len(order):] + order[:k % len(order)]:
                if name in failed:
                    continue
                loads.append(os.getloadavg()[0])
                try:
                    rows[name] += runners[name].window(min(window_s, duration_s - k * window_s))
                except Exception as e:  # noqa: BLE001 - a peer that dies mid-run (dora's daemon stops a node it
                    # finds stuck on a loaded machine) is reported as failed, never as a number; ours must not fail
                    if name.startswith("framework"):
                        raise
                    failed[name] = f"failed in round {k + 1}: {type(e).__name__}: {str(e)[-300:]}"
            if on_round is not None:
                on_round()
    finally:
        for r in runners.values():  # the peers' processes and the runtime's Ray actors alike
            if hasattr(r, "close"):
                r.close()
    out: dict[str, Any] = {}
    for name, r in runners.items():
        if name.startswith("framework"):
            out[name] = r.report(rows[name], kind, stub_ms)
    for name in PEERS:
        if name in failed:
            out[name] = {"available": False, "reason": failed[name]}
        else:
            out[name] = ({"available": True, **overheads(rows[name], kind, stub_ms)} if name in runners
                         else {"available": False, "reason": missing[name]})
    return out


def _row(width: int, height: int, kind: str, layout: str, rep: dict) -> dict:
    cols = {"bare_loop": "bare_loop_overhead_ms", "naive_ray": "naive_ray_overhead_ms",
            "dora_rs": "dora_rs_overhead_ms", "dora_rs_grouped": "dora_rs_grouped_overhead_ms"}
    fw = rep.get(f"framework:{layout}")
    row: dict[str, Any] = {"resolution": f"{width}x{height}", "detector": kind, "fps": int(FPS), "layout": layout,
                           "status": "measured" if fw else NOT_MEASURED,
                           "framework_overhead_ms": mp(fw["framework_overhead_ms"]) if fw else None}
    for name, key in cols.items():
        row[key] = mp(rep[name]["framework_overhead_ms"]) if rep[name]["available"] else None
    row["honest_overhead_ms"] = {name: (mp(r.get("honest_overhead_ms")) if r.get("available", True) else None)
                                 for name, r in (("framework", fw or {"available": False}),
                                                 *((n, rep[n]) for n in cols))}
    bo = row["bare_loop_overhead_ms"]
    row["ratio_median"] = (row["framework_overhead_ms"]["median"] / bo["median"]
                           if fw and bo and bo["median"] and row["framework_overhead_ms"]["median"] is not None
                           else None)
    row["framework"] = fw if fw else {"status": NOT_MEASURED}
    if fw and rep.get(f"framework_unrecorded:{layout}"):  # --record: the same runtime unrecorded, same rotation
        un = rep[f"framework_unrecorded:{layout}"]
        row["framework_unrecorded_overhead_ms"] = mp(un["framework_overhead_ms"])
        row["honest_overhead_ms"]["framework_unrecorded"] = mp(un["honest_overhead_ms"])
        row["framework_unrecorded"] = un
    for name in cols:
        row[name] = rep[name]
    return row


def run_overhead(duration_s: float = 20.0, stub_ms: float = 10.0, kinds: tuple[str, ...] = ("stub", "yolox"),
                 resolutions: tuple[tuple[int, int], ...] = RESOLUTIONS, layouts: tuple[str, ...] = ("colocated",),
                 window_s: float = 5.0, record: bool = False, settle_s: float = 4.0) -> dict:
    """The benchmark's report (see the module docstring): every pipeline, per detector kind and resolution,
    ``duration_s`` seconds in windows of ``window_s``; each AeroDaaS mission flies ``settle_s`` seconds at its
    altitude before its window. Starts and stops its own local Ray."""
    machine = machine_info()
    ray_start.ensure_ray()

    results, loads = [], []
    record_dir = tempfile.mkdtemp(prefix="aerodaas-overhead-rec-") if record else None
    rounds = max(1, math.ceil(duration_s / window_s))
    try:
        with bench_progress("bench overhead", total=len(kinds) * len(resolutions) * rounds) as (progress, task):
            for kind in kinds:
                for wdt, hgt in resolutions:
                    progress.update(task, description=f"bench overhead {kind} {wdt}x{hgt}")
                    rep = interleaved(wdt, hgt, kind, duration_s, window_s, stub_ms, record_dir, loads, layouts,
                                      on_round=lambda: progress.advance(task), settle_s=settle_s)
                    for layout in layouts:
                        row = _row(wdt, hgt, kind, layout, rep)
                        results.append(row)
                        progress.console.print(_line(row))
    finally:
        ray_start.shutdown_ray()
        if record_dir:
            shutil.rmtree(record_dir, ignore_errors=True)
    return {"benchmark": "overhead", "machine": machine, "duration_s": duration_s, "window_s": window_s,
            "settle_s": settle_s, "stub_ms": stub_ms, "recorded": record, "layouts": list(layouts),
            "load": {"load_avg_1min_at_windows": {**summary(loads), "min": min(loads, default=None),
                                                  "max": max(loads, default=None)},
                     "load_avg_1min_end": round(os.getloadavg()[0], 2)},
            "definition": "framework overhead = end-to-end (frame ready -> command applied to the vehicle backend) "
                          "- inference - post-processing, per frame whose command reached the drone; honest "
                          "overhead (stub) = end-to-end + capture dispatch - the stub's nominal time",
            "targets": {"median_ms": 1.0, "p99_ms": 5.0, "ratio_median": 10.0}, "results": results}


def _fmt(mp_: dict | None) -> str:
    return "n/a" if not mp_ or mp_.get("median") is None else f"{mp_['median']:.3f}/{mp_['p99']:.3f}"


def _line(row: dict) -> str:
    return (f"overhead {row['detector']:5s} {row['resolution']} {row['layout']:15s} median/p99 ms: "
            f"framework {_fmt(row['framework_overhead_ms'])} | bare {_fmt(row['bare_loop_overhead_ms'])} | "
            f"naive Ray {_fmt(row['naive_ray_overhead_ms'])} | dora-rs {_fmt(row['dora_rs_overhead_ms'])} | "
            f"dora-rs grouped {_fmt(row['dora_rs_grouped_overhead_ms'])}"
            + "".join(f" | {k[:-3]} {_fmt(v)}" for k, v in ((row.get("framework") or {}).get("hop_ms") or {}).items()))


def _parse_resolutions(values: list[str] | None) -> tuple[tuple[int, int], ...]:
    if not values:
        return RESOLUTIONS
    res = tuple(tuple(int(v) for v in r.lower().split("x")) for r in values)
    if any(len(r) != 2 or min(r) <= 0 for r in res):
        raise ValueError
    return res  # type: ignore[return-value]


def main(a: argparse.Namespace) -> int:
    """``aerodaas bench overhead`` with the options of :mod:`aerodaas.bench.parsers`: checks them (exit 2 naming a bad
    one), runs the benchmark and prints its report; returns the exit code."""
    try:
        res = _parse_resolutions(a.resolution)
    except ValueError:
        print(f"aerodaas bench overhead: --resolution expects WxH with positive integers, got {a.resolution}",
              file=sys.stderr)
        return 2
    for name in ("duration", "window"):
        if not getattr(a, name) > 0:
            print(f"aerodaas bench overhead: --{name} must be > 0 seconds, got {getattr(a, name)}", file=sys.stderr)
            return 2
    if a.stub_ms < 0:
        print(f"aerodaas bench overhead: --stub-ms must be >= 0, got {a.stub_ms}", file=sys.stderr)
        return 2
    if not a.settle >= 0:
        print(f"aerodaas bench overhead: --settle must be >= 0 seconds, got {a.settle}", file=sys.stderr)
        return 2
    kinds = ("stub", "yolox") if a.detector == "both" else (a.detector,)
    if "yolox" in kinds:
        try:
            resolve_model("yolox_nano")
            if not os.environ.get("AERODAAS_DATA_DIR"):
                raise ModelNotFoundError("AERODAAS_DATA_DIR is not set (the YOLOX run flies over real imagery)")
        except (ModelNotFoundError, OSError) as e:
            print(f"aerodaas bench overhead: the YOLOX-Nano configuration needs the model and imagery: {e}",
                  file=sys.stderr)
            return 2
    layouts = {"both": ("colocated", "actors"), "all": LAYOUTS}.get(a.layout, (a.layout,))
    if a.lockstep and f"actors{LOCKSTEP}" not in layouts:
        layouts = (*layouts, f"actors{LOCKSTEP}")

    emit_report(run_overhead(a.duration, a.stub_ms, kinds, res, layouts, a.window, a.record, a.settle), a.out, a.json)
    return 0
