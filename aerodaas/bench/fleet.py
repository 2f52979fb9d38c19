"""``aerodaas bench fleet``: how many simulated drones one 2-core node carries, as drone actors.

For each fleet size N (default 1, 5, 10, 20, 40) and each grouping k (``--drones-per-actor``, default 1: one drone
actor per drone) on a fresh local Ray: N simulated drones, each with a camera (640x480 at 15 FPS), odometry
(10 Hz), the stat-stream and a navigation (control) loop at 10 Hz flying its own survey, and a lightweight
analytics colocated with each drone (in its drone actor), in real time (speedup 1) for ``--duration`` seconds.
``--edge-nodes M`` (M >= 1) runs each fleet on a fresh :class:`~aerodaas.clusters.local.LocalCluster` with M
``tier=edge`` nodes (the first is the head: GCS and driver), one edge compute resource per node (its own
``aerodaas/site`` label), the drones spread over them round-robin, recorded with ``recording.per_node`` into a
temporary directory, and reports each node (``nodes``: :mod:`aerodaas.bench.fleet_nodes`) — the fit of
:mod:`aerodaas.bench.fleet_model` reads them. Reported per run: missed control ticks (%: a tick that runs
more than one control period late), frames dropped (%: camera ticks whose frame never reached the analytics), CPU
(% of one core, all Ray processes and the driver), the summed RSS (and PSS) of every Ray process and the driver at
its peak, and the Ray worker processes (one per drone actor, plus the recorder's). ``--no-camera``: the drones
carry no camera and no analytics (odometry, stat-stream and control only; the report's ``camera`` is None and its
rows count no camera tick). ``--plot FILE`` draws the curve against N as a PNG there (no figure without it: a
benchmark writes no file it was not given); its absolute path is printed on stderr and given as ``"plot"`` in the
JSON report.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import psutil
import ray

from aerodaas.app.api import Environment
from aerodaas.bench.bare_actor import BareActor
from aerodaas.bench.fleet_analytics import FrameExposure
from aerodaas.bench.fleet_nodes import ClusterLayout, FlightWindow, drones_in_actor, node_report, recorder_throughput
from aerodaas.bench.fleet_profile import ActorProfiler
from aerodaas.bench.machine import machine_info
from aerodaas.bench.output import emit_report
from aerodaas.bench.procs import MemorySampler, cpu_seconds, ray_processes
from aerodaas.bench.progress import bench_progress
from aerodaas.clusters.local import LocalCluster
from aerodaas.config import parse_environment_config
from aerodaas.model.types import AeroNavigation, NavigationType, SchedulingType, Waypoint
from aerodaas.runtime import ray_start
from aerodaas.runtime.options import RunOptions
from aerodaas.runtime.ray_start import RayStartError
from aerodaas.schedulers import TrajectoryScheduler

DEFAULT_SIZES = (1, 5, 10, 20, 40)
#: each drone's camera (``--no-camera``: none): pixels and frames per second, as :func:`fleet_config` makes it
CAMERA = {"width": 640, "height": 480, "fps": 15.0}


def fleet_config(n: int, fps: float = 15.0, width: int = 640, height: int = 480, drones_per_actor: int = 1,
                 edge_nodes: int = 1, labelled: bool = False, camera: bool = True) -> dict:
    """environment.json dict for ``n`` drones 6 m apart on a grid, each flying a 4 m square over and over;
    ``drones_per_actor`` drones share a drone actor; ``edge_nodes`` > 1 (or ``labelled``): one edge compute per
    node (label ``aerodaas/site: site<j>``), drone i flying from compute ``edge<i % edge_nodes>``. ``camera``
    False: no camera sensor (odometry, stat-stream and control only)."""
    robots = []
    side = max(1, math.ceil(math.sqrt(n)))
    labelled = labelled or edge_nodes > 1
    for i in range(n):
        robots.append({
            "id": f"d{i:02d}", "backend": "sim", "takeoff_altitude": 3.0, "control_rate_hz": 10,
            **({"compute": f"edge{i % edge_nodes}"} if labelled else {}),
            "limits": {"max_speed": 2.0, "max_vertical_speed": 1.0, "max_acceleration": 2.0},
            "sensors": [
                *([{"id": "cam", "type": "camera",
                    "properties": {"width": width, "height": height, "hfov_deg": 78, "fps": fps, "pitch_deg": 90}}]
                  if camera else []),
                {"id": "odom", "type": "odometry", "properties": {"rate_hz": 10}},
                {"id": "stat", "type": "stat_stream"}]})
    compute = ([{"id": f"edge{j}", "tier": "edge", "labels": {"aerodaas/site": f"site{j}"}} for j in range(edge_nodes)]
               if labelled else [{"id": "edge", "tier": "edge"}])
    return {"name": f"fleet-{n}", "robots": robots, "compute": compute, "drones_per_actor": drones_per_actor,
            "world": {"ground": {"seed": 3, "metres_per_pixel": 0.05, "size_m": 12.0 * side + 40}},
            "simulation": {"speedup": 1.0, "lockstep": False, "physics_hz": 50}}


def _grid_offset(i: int, n: int) -> tuple[float, float]:
    side = max(1, math.ceil(math.sqrt(n)))
    return (6.0 * (i % side), 6.0 * (i // side))


def build_fleet(n: int, drones_per_actor: int = 1, edge_nodes: int = 1, cluster: bool = False,
                camera: bool = True):
    """The fleet application: environment, an analytics colocated with each drone's camera, a looping survey per
    drone. ``cluster``: one labelled edge compute per node (even for one node) and ``recording.per_node``.
    ``camera`` False: no camera and no analytics (the analytics returned is None)."""
    cfg = fleet_config(n, drones_per_actor=drones_per_actor, edge_nodes=edge_nodes, labelled=cluster, camera=camera)
    if cluster:
        cfg["recording"] = {"per_node": True}
    env = Environment(parse_environment_config(cfg))
    shared = None
    if camera:
        shared = FrameExposure()
        shared.deploy(env.get_compute_resources()[0], colocate=True)  # a copy inside each drone's actor
    sched = TrajectoryScheduler(env)
    env.set_trajectory_scheduler(sched)  # one scheduler plugged in; each drone gets its own queue at start
    for i, drone in enumerate(env.get_env_robots()):
        if shared is not None:
            shared.analyse(drone.get_sensor_by_id("cam").get_data_stream())
        ox, oy = _grid_offset(i, n)
        square = [(0, 0), (4, 0), (4, 4), (0, 4)]
        wps = [Waypoint(id=f"w{k}", x=ox + square[k % 4][0], y=oy + square[k % 4][1], z=3.0, hover_duration=0.5)
               for k in range(400)]
        drone.navigate(sched.generate_navigation(AeroNavigation(NavigationType.DISTANCE_DRIVEN, wps,
                                                                SchedulingType.ORDERED)))
    return env, shared


def _start_cluster(edge_nodes: int) -> LocalCluster:
    """A LocalCluster of ``edge_nodes`` ``tier=edge`` nodes (node j labelled ``aerodaas/site: site<j>``; the first
    is the head, with the GCS and the driver), no cloud node, workers at niceness 0 like the local Ray's. Raises
    RayStartError when a node did not start (Ray's own ``Exception``: a raylet's registration timed out under load;
    :func:`_run_size_started` tries again)."""
    try:
        return LocalCluster(cloud_nodes=0, edge_nodes=edge_nodes, worker_niceness=0,
                            edge_labels=[{"aerodaas/site": f"site{j}"} for j in range(edge_nodes)])
    except Exception as e:  # noqa: BLE001 - ray._private.node raises a bare Exception for a node's start timeout
        raise RayStartError(f"the local cluster of {edge_nodes} edge node(s) did not start: {e}") from e


def _cluster_part(window: FlightWindow, lc: LocalCluster, env: Any, res: Any, rec_dir: str, mission_s: float) -> dict:
    """The cluster-only fields of a row: ``nodes`` (:func:`~aerodaas.bench.fleet_nodes.node_report`), the GCS's
    actor count, the run recorder's throughput, the recording's losses and whether the window was whole."""
    n_nodes = len(lc.edge_nodes)
    robot_node = {r.id: i % n_nodes for i, r in enumerate(env.get_env_robots())}
    recordings = {j: sorted(Path(rec_dir).glob(f"fleet.node-edge{j}.mcap")) for j in range(n_nodes)}
    layout = ClusterLayout([nd.node_id for nd in lc.edge_nodes], str(res.stats.get("_plan", {}).get("run")),
                           robot_node, recordings)
    main_rec = sorted(Path(rec_dir).glob("fleet.mcap"))
    return {"nodes": node_report(window, layout, res, mission_s),
            "gcs_actors": sum(1 for a in window.actors if a["state"] == "ALIVE"),
            "gcs_actor_classes": {c: sum(1 for a in window.actors if a["state"] == "ALIVE" and a["class"] == c)
                                  for c in sorted({str(a["class"]) for a in window.actors})},
            "run_recorder": recorder_throughput(main_rec, mission_s) if main_rec else None,
            "recording_lost": int((res.recording_accounting or {}).get("lost_total", 0)),
            "recording_accounting_read": res.recording_accounting is not None,
            "window": {"complete": window.complete, "seconds": round(window.measured_s, 2), "error": window.error}}


def run_size(n: int, duration_s: float, drones_per_actor: int = 1, edge_nodes: int | None = None,
             profile: bool = False, camera: bool = True) -> dict:
    """One fleet size on a fresh local Ray (``edge_nodes`` None) or a fresh LocalCluster of ``edge_nodes`` edge
    nodes, recorded with one recorder per node into a temporary directory (removed after; only the numbers are
    kept); returns the measured row (with ``nodes`` on a cluster). ``profile``: also the cost table of one drone
    actor and of the node's processes (:class:`~aerodaas.bench.fleet_profile.ActorProfiler`, local Ray only), as
    ``"profile"`` in the row, with an idle :class:`~aerodaas.bench.bare_actor.BareActor` measured beside the fleet
    (left out of the row's processes, CPU and memory). ``camera`` False: the drones fly without cameras (no frame is
    made or analysed)."""
    ray_start.shutdown_ray()
    opts = RunOptions(progress=False)
    cluster = edge_nodes is not None
    env, _ = build_fleet(n, drones_per_actor, edge_nodes or 1, cluster, camera)
    lc, nodes, window, extra = None, None, None, {}
    with tempfile.TemporaryDirectory(prefix="aerodaas-bench-fleet-") as rec_dir:
        if cluster:
            lc = _start_cluster(edge_nodes)
            nodes = lc.cluster.list_all_nodes()
            opts.address, opts.record = lc.address, os.path.join(rec_dir, "fleet.mcap")
            window = FlightWindow(lc.edge_nodes, settle_s=min(3.0, duration_s / 4),
                                  window_s=max(1.0, duration_s * 0.75 - min(3.0, duration_s / 4) - 0.5))
            for robot in env.get_env_robots():
                robot.on_mission_start(window.begin)
        try:
            ray_start.ensure_ray(opts.address)
            prof, floor, bare = None, None, ()
            if profile and not cluster:  # the floor, measured beside the fleet and left out of its rows; the
                floor = BareActor.remote()  # handle is kept to the end (Ray ends an actor whose handles are gone)
                bare = (ray.get(floor.pid.remote(), timeout=120),)
            time.sleep(2.0)  # let Ray's own processes settle before measuring
            procs = ray_processes(nodes, bare)
            cpu0, wall0 = cpu_seconds(procs), time.monotonic()
            if profile and not cluster:
                # the window: after the fleet's start (its actors up and flying), within the flight
                prof = ActorProfiler(n, min(drones_per_actor, n), bare_pid=bare[0],
                                     window_s=max(2.0, min(10.0, duration_s / 2))).start()
            with MemorySampler(1.0, nodes, bare) as mem:
                res = env.start_mission(timeout=duration_s, options=opts)
            for m in (prof, window):
                if m is not None:
                    m.stop()
            wall = time.monotonic() - wall0
            cpu = cpu_seconds(ray_processes(nodes, bare)) - cpu0
            mission_s = float(res.stats.get("_timing", {}).get("mission_s", wall))
            if window is not None:
                extra = _cluster_part(window, lc, env, res, rec_dir, mission_s)
        finally:
            ray_start.shutdown_ray()
            if lc is not None:
                lc.shutdown()
    return {**_row(n, drones_per_actor, edge_nodes, res, wall, cpu, mem, lc), **extra,
            **({"profile": prof.result if prof.result is not None else {"error": prof.error or "window missed"}}
               if prof is not None else {})}


def _row(n: int, drones_per_actor: int, edge_nodes: int | None, res: Any, wall: float, cpu: float,
         mem: MemorySampler, lc: LocalCluster | None) -> dict:
    """The row of one fleet size from its run's result ``res``: the whole fleet's ticks, frames, CPU and memory."""
    ticks = sum(r.get("ticks", 0) for r in res.robots.values())
    missed = sum(r.get("missed_ticks", 0) for r in res.robots.values())
    cam_ticks = sum(c.get("ticks", 0) for s in res.stats.values() if isinstance(s, dict)
                    for c in s.get("cameras", {}).values())
    analysed = sum((a or {}).get("processed", 0) for rid in res.robots
                   for a in res.stats.get(rid, {}).get("analytics", []))
    hosts = res.stats.get("_hosts", {})
    lateness = [h["tick_lateness_ms"] for h in hosts.values() if (h.get("tick_lateness_ms") or {}).get("n")]
    plan = res.stats.get("_plan", {})
    names = {nd.node_id: f"edge node {j}" for j, nd in enumerate(lc.edge_nodes)} if lc else {}
    per_node: dict[str, int] = {}
    for hid, node in (plan.get("placed") or {}).items():
        if hid and hid.startswith("drone"):
            per_node[names.get(node, node)] = per_node.get(names.get(node, node), 0) + drones_in_actor(hid)
    return {"drones": n, "drones_per_actor": drones_per_actor, "edge_nodes": edge_nodes,
            # duration_s: the measured (flying) part; wall_s also holds the actors' start and close
            "duration_s": round(float(res.stats.get("_timing", {}).get("mission_s", wall)), 1),
            "wall_s": round(wall, 1), "startup_s": res.stats.get("_timing", {}).get("startup_s"),
            "ticks": ticks, "missed_ticks": missed,
            "missed_ticks_pct": 100.0 * missed / max(ticks, 1), "camera_ticks": cam_ticks, "frames_analysed": analysed,
            "dropped_frames_pct": 100.0 * (cam_ticks - analysed) / max(cam_ticks, 1),
            "cpu_pct": 100.0 * cpu / max(wall, 1e-9),  # over wall_s, the span the CPU time was sampled over
            "rss_mb": round(mem.peak["rss_mb"], 1),
            "pss_mb": round(mem.peak["pss_mb"], 1), "processes": mem.peak["processes"],
            "worker_processes": mem.peak.get("worker_processes", 0), "drones_per_node": per_node,
            "process_rows": mem.peak["rows"],
            "tick_lateness_ms": {"median": float(np.median([x["median"] for x in lateness])) if lateness else None,
                                 "p99": max((x["p99"] for x in lateness), default=None)},
            "host_errors": sum(h.get("error_count", 0) for h in hosts.values()),
            **drone_actor_cpu(hosts),
            "outcome": res.outcome,
            "outcomes": sorted({str(r.get("outcome")) for r in res.robots.values()})}


def drone_actor_cpu(hosts: dict) -> dict:
    """The drone actors' CPU over their runs, exactly, from each actor's own accounts
    (:meth:`~aerodaas.actors.host.assembly.ActorAssembly.cpu_accounts`, in ``hosts``: host id -> its ``_host``
    stats), in CPU-seconds per drone per simulated second: every thread of the drone actors (``all``), of it the
    cameras' frame making, the analytics' ``process`` calls and the JPEG encodes of recorded frames, and what is
    left, the framework's share (``framework_cpu_s_per_drone_per_sim_s``, also given alone). Empty when no drone
    actor reported a run (all lost)."""
    from aerodaas.actors.host.assembly import USER_CPU_PARTS  # lazy: heavy OpenCV; the run's actors import it anyway

    flown = [h["cpu"] for h in hosts.values() if (h.get("cpu") or {}).get("flight_sim_s")]
    drone_s = sum(c["drones"] * c["flight_sim_s"] for c in flown)
    if not drone_s:
        return {}
    total = sum(c["flight_cpu_s"] for c in flown)
    user = {k: sum(c.get(k, 0.0) for c in flown) for k in USER_CPU_PARTS}
    framework = total - sum(user.values())
    return {"framework_cpu_s_per_drone_per_sim_s": round(framework / drone_s, 4),
            "drone_actor_cpu_s_per_drone_per_sim_s": {
                "all": round(total / drone_s, 4), "camera frame making": round(user["render_cpu_s"] / drone_s, 4),
                "analytics process calls": round(user["analytics_cpu_s"] / drone_s, 4),
                "recorded frames' JPEG encode": round(user["encode_cpu_s"] / drone_s, 4),
                "framework": round(framework / drone_s, 4)}}


#: attempts at a fleet size whose local Ray did not start (each after :func:`~aerodaas.runtime.ray_start.ensure_ray`'s
#: own three): on a machine at load 30-50, Ray's raylet missed its 30 s registration with the GCS that often
RAY_START_ATTEMPTS = 4


def _run_size_started(progress: Any, n: int, duration_s: float, k: int, edge_nodes: int | None,
                      profile: bool, camera: bool = True) -> dict:
    """:func:`run_size`, started again (at most :data:`RAY_START_ATTEMPTS` times) when its Ray did not start: no
    drone flew then, so nothing of the measurement is lost or repeated. Raises the last RayStartError."""
    for attempt in range(1, RAY_START_ATTEMPTS + 1):
        try:
            return run_size(n, duration_s, k, edge_nodes, profile, camera)
        except RayStartError as e:
            if attempt == RAY_START_ATTEMPTS:
                raise
            progress.console.print(f"fleet N={n} k={k}: Ray did not start ({e}); attempt {attempt + 1} of "
                                   f"{RAY_START_ATTEMPTS}")
            time.sleep(10.0)
    raise AssertionError("unreachable")


def run_fleet(sizes: tuple[int, ...] = DEFAULT_SIZES, duration_s: float = 30.0, groupings: tuple[int, ...] = (1,),
              edge_nodes: int | None = None, runs: tuple[tuple[int, int], ...] = (), profile: bool = False,
              camera: bool = True) -> dict:
    """Every (size, grouping) pair of ``sizes`` x ``groupings``, or exactly ``runs`` ((drones, drones per actor)
    pairs, in order) when given, on the local Ray (``edge_nodes`` None) or a fresh local cluster of ``edge_nodes``
    edge nodes per run; the report with a row per run and the machine and load at the start. ``camera`` False:
    drones without cameras (the report's ``camera`` is None)."""
    machine, load_start = machine_info(), round(os.getloadavg()[0], 2)  # before the fleet's own processes load it
    rows = []
    pairs = [(k, n) for n, k in runs] if runs else [(k, n) for k in groupings for n in sizes]
    with bench_progress("bench fleet", total=len(pairs)) as (progress, task):
        for k, n in pairs:
            progress.update(task, description=f"bench fleet N={n} k={k}")
            row = _run_size_started(progress, n, duration_s, k, edge_nodes, profile, camera)
            row["load_avg_1min_end"] = round(os.getloadavg()[0], 2)
            progress.advance(task)
            progress.console.print(
                f"fleet N={n:3d} k={k}: missed ticks {row['missed_ticks_pct']:.2f}%  "
                + (f"frames dropped {row['dropped_frames_pct']:.1f}%" if camera else "no cameras")
                + f"  CPU {row['cpu_pct']:.0f}%  RSS {row['rss_mb']:.0f} MB "
                f"(PSS {row['pss_mb']:.0f} MB, {row['worker_processes']} workers, {row['processes']} processes)"
                + (f"  framework {row['framework_cpu_s_per_drone_per_sim_s']:.4f} CPU-s per drone per sim s"
                   if "framework_cpu_s_per_drone_per_sim_s" in row else "")
                + (f"  per node {row['drones_per_node']}, GCS actors {row.get('gcs_actors')}" if edge_nodes else "")
                + (f"  RECORDING LOST {row['recording_lost']} messages" if row.get("recording_lost") else "")
                + (f"  node window incomplete: {row['window']}" if row.get("window", {}).get("complete") is False
                   else ""))
            rows.append(row)
    for r in rows:
        # the one-drone row of the same grouping, else any (one drone is one actor whatever the grouping)
        one = next((o for o in rows if o["drones"] == 1 and o["drones_per_actor"] == r["drones_per_actor"]),
                   next((o for o in rows if o["drones"] == 1), None))
        r["rss_mb_per_extra_drone"] = ((r["rss_mb"] - one["rss_mb"]) / (r["drones"] - 1)
                                       if one and r["drones"] > 1 else None)
        r["pss_mb_per_extra_drone"] = ((r["pss_mb"] - one["pss_mb"]) / (r["drones"] - 1)
                                       if one and r["drones"] > 1 else None)
        actors = math.ceil(r["drones"] / r["drones_per_actor"])
        r["pss_mb_per_extra_actor"] = (r["pss_mb"] - one["pss_mb"]) / (actors - 1) if one and actors > 1 else None
    return {"benchmark": "fleet", "machine": machine, "duration_s": duration_s, "edge_nodes": edge_nodes,
            "camera": dict(CAMERA) if camera else None, "load_avg_1min_start": load_start, "results": rows,
            "targets": {"missed_ticks_pct_below": 1.0, "drones_at_least": 20, "drones_at_least_grouped": 40,
                        "rss_mb_per_extra_drone_max": 150}}


#: memory a cluster run needs before it starts, MiB (PSS measured in docs/results/cluster.md, rounded up:
#: 402, 210 and 86): the head's extra (GCS, the benchmark's driver, the run's recorder, head-only agents), each
#: node's fixed processes (raylet, Ray's agents, log monitor, its recorder actor) and each drone actor
HEAD_EXTRA_MB, NODE_FIXED_MB, DRONE_ACTOR_MB = 450.0, 250.0, 90.0


def check_edge_nodes(edge_nodes: int, runs: tuple[tuple[int, int], ...], available_mb: float) -> str | None:
    """Why ``--edge-nodes edge_nodes`` cannot carry ``runs`` ((drones, drones per actor) pairs) on this machine, or
    None: fewer than one node, more nodes than a run's drones (a node would carry none), or more memory than
    ``available_mb`` (MiB; :data:`HEAD_EXTRA_MB` + nodes x :data:`NODE_FIXED_MB` + drone actors x
    :data:`DRONE_ACTOR_MB` for the largest run)."""
    if edge_nodes < 1:
        return f"--edge-nodes must be >= 1, got {edge_nodes}"
    fewest = min(n for n, _ in runs)
    if fewest < edge_nodes:
        return (f"--edge-nodes {edge_nodes} needs at least {edge_nodes} drones in every run (one per node), "
                f"got a run of {fewest}")
    actors = max(math.ceil(n / k) for n, k in runs)
    need = HEAD_EXTRA_MB + edge_nodes * NODE_FIXED_MB + actors * DRONE_ACTOR_MB
    if need > available_mb:
        return (f"--edge-nodes {edge_nodes} with {actors} drone actors needs about {need:,.0f} MiB "
                f"({HEAD_EXTRA_MB:.0f} + {edge_nodes} x {NODE_FIXED_MB:.0f} per node + {actors} x "
                f"{DRONE_ACTOR_MB:.0f} per drone actor); this machine has {available_mb:,.0f} MiB available")
    return None


def parse_run(text: str) -> tuple[int, int]:
    """``"N:K"`` -> (N drones, K per actor), both >= 1. Raises ValueError naming ``--run`` and the value."""
    try:
        n, k = (int(x) for x in text.split(":"))
    except ValueError:
        raise ValueError(f"--run must be N:K (drones:drones per actor, e.g. 40:1), got {text!r}") from None
    if n < 1 or k < 1:
        raise ValueError(f"--run N:K needs N >= 1 and K >= 1, got {text!r}")
    return n, k


def plot_fleet(report: dict, path: str) -> None:
    """Four panels against N, one curve per grouping k (drones per actor): missed ticks %, frames dropped %, CPU %,
    PSS MB."""
    import matplotlib  # lazy: heavy dependency (matplotlib)

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: heavy dependency (matplotlib)

    by_k: dict[int, list] = {}
    for r in report["results"]:
        by_k.setdefault(int(r.get("drones_per_actor", 1)), []).append(r)
    fig, ax = plt.subplots(1, 4, figsize=(16, 3.6))
    for k, rows in sorted(by_k.items()):
        n = [r["drones"] for r in rows]
        lab = f"{k} drone(s) per actor"
        ax[0].plot(n, [r["missed_ticks_pct"] for r in rows], "o-", label=lab)
        ax[1].plot(n, [r["dropped_frames_pct"] for r in rows], "o-", label=lab)
        ax[2].plot(n, [r["cpu_pct"] for r in rows], "o-", label=lab)
        ax[3].plot(n, [r["pss_mb"] for r in rows], "s-", label=f"PSS, {lab}")
    ax[0].axhline(1.0, color="r", ls="--", lw=1, label="target < 1 %")
    ax[0].set_title("missed control ticks (%)")
    ax[1].set_title("frames dropped (%)")
    ax[2].axhline(200, color="grey", ls=":", lw=1, label="2 cores")
    ax[2].set_title("CPU (% of one core)")
    ax[3].set_title("memory of all Ray processes (MB)")
    for a in ax:
        a.set_xlabel("drones")
        a.grid(alpha=0.3)
        if a.get_legend_handles_labels()[0]:
            a.legend(fontsize=7)
    fig.suptitle(f"aerodaas bench fleet — {report['machine']['cpu_count']} cores, {report['duration_s']:.0f} s per size")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(a: argparse.Namespace) -> int:
    """``aerodaas bench fleet`` with the options of :mod:`aerodaas.bench.parsers`: checks them (exit 2 naming a bad
    one), runs the benchmark and prints its report; returns the exit code."""
    if a.duration <= 0:
        print(f"aerodaas bench fleet: --duration must be > 0, got {a.duration}", file=sys.stderr)
        return 2
    sizes = tuple(a.drones) if a.drones else DEFAULT_SIZES
    if any(s < 1 for s in sizes):
        print(f"aerodaas bench fleet: --drones must be >= 1, got {list(sizes)}", file=sys.stderr)
        return 2
    per_actor = tuple(a.per_actor) if a.per_actor else (1,)
    if any(k < 1 for k in per_actor):
        print(f"aerodaas bench fleet: --drones-per-actor must be >= 1, got {list(per_actor)}", file=sys.stderr)
        return 2
    try:
        runs = tuple(parse_run(r) for r in (a.runs or []))
    except ValueError as e:
        print(f"aerodaas bench fleet: {e}", file=sys.stderr)
        return 2
    if a.edge_nodes is not None:
        problem = check_edge_nodes(a.edge_nodes, runs or tuple((n, k) for k in per_actor for n in sizes),
                                   psutil.virtual_memory().available / 2**20)
        if problem:
            print(f"aerodaas bench fleet: {problem}", file=sys.stderr)
            return 2
    report = run_fleet(sizes, a.duration, per_actor, a.edge_nodes, runs, a.profile, not a.no_camera)
    if a.plot:
        report["plot"] = os.path.abspath(a.plot)

    emit_report(report, a.out, a.json)
    if a.plot:
        plot_fleet(report, a.plot)
        print(f"aerodaas bench fleet: curve written to {report['plot']}", file=sys.stderr, flush=True)
    return 0
