"""Runtime glue: turns an application's dataflow into Ray actors placed on tiers, runs the mission, shows
progress, finishes the recording and returns a :class:`MissionResult`.

Placement uses Ray node labels: actors for compute on tier ``edge`` get ``label_selector={"tier": "edge"}``,
tier ``cloud`` ``{"tier": "cloud"}``. In local single-node mode (the default) Ray is started here with the
node labelled ``tier=edge`` and cloud compute is allowed on it (``in(edge,cloud)``). Ray's token
authentication stays on (Ray >= 2.59 enables it for local clusters).
"""
from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, field
from typing import Any


from .config import SimulationConfig


@dataclass
class RunOptions:
    """Options the CLI (or a test) sets before running an application."""

    record: str | None = None
    speedup: float | None = None
    lockstep: bool | None = None
    timeout: float | None = None
    address: str | None = None
    env_path: str | None = None
    progress: bool = True
    hitl: bool | None = None  # force the human-in-the-loop API on/off (default: environment.json hitl.enabled)
    hitl_port: int | None = None


OPTIONS = RunOptions()


@dataclass
class MissionResult:
    """Outcome of a mission: ``outcome`` (success / incomplete / timeout / interrupted / failed), per-robot
    reports (visited waypoints, events, state history), per-actor stats, per-frame latency and the recording."""

    outcome: str
    robots: dict[str, dict]
    stats: dict[str, Any]
    latency: dict[str, Any]
    recording: str | None
    wall_s: float
    recording_counts: dict[str, int] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.outcome == "success"


_STARTED_RAY = False


def ensure_ray(address: str | None = None) -> bool:
    """Connect to (``address``) or start a local Ray; returns True when the cluster has ``tier=cloud`` nodes."""
    global _STARTED_RAY
    import ray

    if not ray.is_initialized():
        if address:
            ray.init(address=address, log_to_driver=True, include_dashboard=False)
        else:
            ray.init(labels={"tier": "edge"}, include_dashboard=False, log_to_driver=True,
                     num_cpus=max(os.cpu_count() or 2, 4), configure_logging=True, logging_level="warning")
            _STARTED_RAY = True
    return any(n.get("Labels", {}).get("tier") == "cloud" for n in ray.nodes() if n.get("Alive"))


def shutdown_ray() -> None:
    global _STARTED_RAY
    import ray

    if _STARTED_RAY and ray.is_initialized():
        ray.shutdown()
    _STARTED_RAY = False


def _selector(tier: str, has_cloud: bool) -> dict[str, str]:
    if tier == "cloud" and not has_cloud:
        return {"tier": "in(edge,cloud)"}
    return {"tier": tier}


def _collect_graph(robot) -> tuple[list, list]:
    """Analytics reachable from the robot's sensors (topological order) and the sensors in use."""
    order, seen = [], set()

    def visit(stream):
        for sub in stream.subscribers:
            if id(sub) not in seen:
                seen.add(id(sub))
                order.append(sub)
                visit(sub.output)

    for s in robot.sensors.values():
        visit(s.get_data_stream())
    return order, [s for s in robot.sensors.values()]


def run_mission(env, robots: list, timeout: float | None = None) -> MissionResult:
    """Start all actors for ``robots`` of ``env``, fly, and tear down. See module docstring."""
    import ray

    from aerodaas.actors.drone import DroneActor
    from aerodaas.actors.nodes import AnalyticsActor, CameraActor, SchedulerActor
    from aerodaas.actors.recorder import RecorderActor

    opts = OPTIONS
    timeout = opts.timeout if opts.timeout is not None else timeout
    sim = SimulationConfig.model_validate(env.cfg.simulation.model_dump())
    if opts.speedup is not None:
        sim.speedup = opts.speedup
    if opts.lockstep is not None:
        sim.lockstep = opts.lockstep

    # ---- validate everything before any actor starts
    graphs = {}
    for r in robots:
        analytics, _ = _collect_graph(r)
        for a in analytics:
            if a.compute is None:
                a.deploy(env.get_compute_resources()[0])
            check = getattr(a, "check", None)
            if callable(check):
                check()
        graphs[r.id] = analytics
        _check_preplanned(r, r.scheduler or env.trajectory_scheduler())

    t_start = time.monotonic()
    has_cloud = ensure_ray(opts.address)
    epoch_ns = time.time_ns()
    actors: list = []
    recorder = None
    if opts.record:
        meta = {"environment": env.cfg.name, "robots": ",".join(r.id for r in robots), "speedup": str(sim.speedup),
                "lockstep": str(sim.lockstep), "aerodaas": "0.1.0"}
        recorder = RecorderActor.options(label_selector={"tier": "edge"}).remote(os.path.abspath(opts.record), meta)
        actors.append(recorder)
    handles: dict[str, dict] = {}
    hitl = None
    try:
        for r in robots:
            sched = r.scheduler or env.trajectory_scheduler()
            preplanned = sum(sum(1 for i in m.items if type(i).__name__ == "Waypoint")
                             for m in sched._missions if m.distance_driven)
            s_actor = SchedulerActor.options(label_selector={"tier": "edge"}).remote(
                r.id, sched, recorder, epoch_ns, r.cfg.model_dump(mode="json"))
            d_actor = DroneActor.options(label_selector={"tier": "edge"}).remote(
                r.cfg.model_dump(mode="json"), sim.model_dump(), s_actor, recorder, epoch_ns)
            actors += [s_actor, d_actor]
            a_actors = {}
            for a in graphs[r.id]:
                sel = _selector(a.compute.tier, has_cloud)
                h = AnalyticsActor.options(label_selector=sel).remote(a.name, r.id, a, recorder, epoch_ns, sim.lockstep)
                a_actors[id(a)] = h
                actors.append(h)
            cams, cam_handles = [], {}
            for s in r.sensors.values():
                if s.type == "camera" and (s.get_data_stream().subscribers or recorder is not None):
                    h = CameraActor.options(label_selector={"tier": "edge"}).remote(
                        r.id, s.id, s.cfg.properties, env.cfg.world.model_dump(mode="json"), recorder, epoch_ns,
                        sim.lockstep)
                    cams.append((h, float(s.cfg.properties["fps"])))
                    cam_handles[s.id] = h
                    actors.append(h)

            def subs_of(stream) -> list[tuple]:
                out = []
                for sub in stream.subscribers:
                    if id(sub) in a_actors:
                        out.append((a_actors[id(sub)], "push", "in", stream.buffer))
                for st, prio, replace in sched.stream_inputs:
                    if st is stream:
                        out.append((s_actor, "push", f"priority:{prio}" + (":replace" if replace else ""), 4))
                return out

            wiring = []
            for sid, h in cam_handles.items():
                wiring.append(h.connect.remote(subs_of(r.sensors[sid].get_data_stream())))
            for a in graphs[r.id]:
                wiring.append(a_actors[id(a)].connect.remote(subs_of(a.output)))
            odom = [s for s in r.sensors.values() if s.type == "odometry"]
            stat = [s for s in r.sensors.values() if s.type == "stat_stream"]
            odom_subs = [x for s in odom for x in subs_of(s.get_data_stream())]
            state_subs = [x for s in stat for x in subs_of(s.get_data_stream())]
            wiring.append(d_actor.connect.remote(cams, odom_subs, state_subs, preplanned))
            ray.get(wiring + [h.ready.remote() for h in a_actors.values()])
            handles[r.id] = {"robot": r, "drone": d_actor, "scheduler": s_actor, "analytics": a_actors,
                             "cameras": cam_handles, "sched_obj": sched}
            r._handle = d_actor
            sched._remote = s_actor
            for s in r.sensors.values():
                s.get_data_stream()._runtime_getter = _pull_getter(s, d_actor, cam_handles)
            for a in graphs[r.id]:
                a.output._runtime_getter = (lambda h=a_actors[id(a)]: ray.get(h.get_latest.remote()))

        hcfg = env.cfg.hitl
        if opts.hitl if opts.hitl is not None else hcfg.enabled:
            from .hitl import HitlServer

            hitl = HitlServer({rid: {"drone": h["drone"], "scheduler": h["scheduler"]} for rid, h in handles.items()},
                              host=hcfg.host, port=opts.hitl_port if opts.hitl_port is not None else hcfg.port,
                              token=hcfg.token).start()
            env.hitl = hitl
            shown = hitl.token if hitl.generated_token else "(the token from environment.json)"
            print(f"aerodaas: human-in-the-loop API at {hitl.url}  bearer token: {shown}", flush=True)
        for h in handles.values():
            for hook in h["robot"]._start_hooks:
                hook(h["robot"])
        runs = {rid: h["drone"].run.remote(timeout) for rid, h in handles.items()}
        reports = _wait_with_progress(runs, handles, opts.progress)
        stats, latency = _collect_stats(handles)
    finally:
        if hitl is not None:
            hitl.stop()
            env.hitl = None
        counts = {}
        if recorder is not None:
            try:
                counts = ray.get(recorder.close.remote(), timeout=30)
            except Exception as e:  # pragma: no cover - reported, never silently lost
                print(f"aerodaas: warning: recording could not be finished cleanly: {e}", file=sys.stderr)
        for h in handles.values():
            h["robot"]._handle = None
            h["sched_obj"]._remote = None
            for s in h["robot"].sensors.values():
                s.get_data_stream()._runtime_getter = None
        for a in actors:
            ray.kill(a, no_restart=True)
    outcomes = [rep.get("outcome") or "failed" for rep in reports.values()]
    outcome = "success" if outcomes and all(o == "success" for o in outcomes) else next(
        (o for o in outcomes if o != "success"), "failed")
    result = MissionResult(outcome=outcome, robots=reports, stats=stats, latency=latency, recording=opts.record,
                           wall_s=time.monotonic() - t_start, recording_counts=counts)
    for h in handles.values():
        for hook in h["robot"]._end_hooks:
            hook(h["robot"], result)
    return result


def _check_preplanned(robot, sched) -> None:
    """Check every queued mission of ``robot`` against its safety limits before any actor starts (legs chained
    from the take-off point). Raises :class:`aerodaas.safety.SafetyViolation`; clamped items replace the
    originals."""
    from .models import AeroNavigation, SchedulingType
    from .safety import SafetyGate

    gate = SafetyGate(robot.cfg.safety, robot.cfg.limits, robot.cfg.home)
    start = (0.0, 0.0, robot.cfg.takeoff_altitude)
    for m in sched._missions:
        nav = AeroNavigation(waypoints=list(m.items), scheduling_type=SchedulingType.ORDERED, name=m.name)
        m.items = list(gate.check_navigation(nav, start).waypoints)


def _pull_getter(sensor, drone, cams):
    import ray

    def get():
        if sensor.type == "camera" and sensor.id in cams:
            got = ray.get(cams[sensor.id].get_latest.remote())
            return None if got is None else (ray.get(got[0][0]), got[1])
        st = ray.get(drone.status.remote())
        return st if sensor.type == "stat_stream" else ray.get(drone.report.remote()).get("position")

    return get


def _wait_with_progress(runs: dict, handles: dict, progress: bool) -> dict:
    import ray

    pending = dict(runs)
    reports: dict[str, dict] = {}
    interrupted = False
    live = None
    if progress and sys.stdout.isatty():
        from rich.live import Live

        live = Live(refresh_per_second=4, transient=False)
        live.start()
    last_print = 0.0
    t0 = time.monotonic()
    try:
        while pending:
            try:
                ready, _ = ray.wait(list(pending.values()), num_returns=1, timeout=0.5)
            except KeyboardInterrupt:
                raise
            for rid, ref in list(pending.items()):
                if ref in ready:
                    reports[rid] = ray.get(ref)
                    del pending[rid]
            if progress and pending:
                lines = _progress_lines(handles, pending, t0)
                if live is not None:
                    from rich.text import Text

                    live.update(Text("\n".join(lines)))
                elif time.monotonic() - last_print > 5.0:
                    print("\n".join(lines), flush=True)
                    last_print = time.monotonic()
    except KeyboardInterrupt:
        interrupted = True
        for rid in pending:
            try:
                ray.get(handles[rid]["drone"].end_mission.remote("interrupted"), timeout=5)
            except Exception:
                pass
        for rid, ref in pending.items():
            try:
                reports[rid] = ray.get(ref, timeout=20)
            except Exception as e:
                reports[rid] = {"robot": rid, "outcome": "interrupted", "error": str(e)}
    finally:
        if live is not None:
            live.stop()
    if interrupted:
        for rep in reports.values():
            rep["outcome"] = "interrupted"
    return reports


def _progress_lines(handles: dict, pending: dict, t0: float) -> list[str]:
    import ray

    lines = []
    for rid in pending:
        h = handles[rid]
        try:
            st = ray.get(h["drone"].status.remote(), timeout=2)
        except Exception:
            continue
        rendered = st["frames"] - st["frames_dropped_at_camera"]  # frames actually captured, not skipped ticks
        fps = rendered / max(time.monotonic() - t0, 1e-6)
        dets = ""
        for a in h["analytics"].values():
            try:
                s = ray.get(a.stats.remote(), timeout=2)
            except Exception:
                continue
            if "frames_with_detections" in s:
                dets = f" detections {s['frames_with_detections']}/{s['frames']}"
        x, y, z = st["position"]
        lines.append(f"[{rid}] t={st['t']:6.1f}s {st['state']:<13} waypoint {st['visited']}/{st['preplanned_total']} "
                     f"pos=({x:6.1f},{y:6.1f},{z:5.1f}) battery {st['battery_pct']:5.1f}% "
                     f"camera {fps:5.1f} FPS dropped {st['frames_dropped_at_camera']}{dets}")
    return lines


def _collect_stats(handles: dict) -> tuple[dict, dict]:
    import ray

    stats: dict[str, Any] = {}
    latency: dict[str, Any] = {}
    for rid, h in handles.items():
        s: dict[str, Any] = {"scheduler": ray.get(h["scheduler"].stats.remote())}
        s["cameras"] = {sid: ray.get(c.stats.remote()) for sid, c in h["cameras"].items()}
        s["analytics"] = [ray.get(a.stats.remote()) for a in h["analytics"].values()]
        stats[rid] = s
        sch = s["scheduler"]
        if "e2e_ms" in sch:
            latency[rid] = {k: sch[k] for k in ("e2e_ms", "overhead_ms", "inference_ms")}
            latency[rid]["frames"] = sch["frames_with_latency"]
    return stats, latency


def format_summary(result: MissionResult) -> str:
    """Human-readable end-of-run summary (what ``aerodaas run`` prints)."""
    lines = [f"mission outcome: {result.outcome}   wall time {result.wall_s:.1f} s"]
    for rid, rep in result.robots.items():
        lines.append(f"  robot {rid}: sim time {rep.get('t', 0):.1f} s, waypoints {rep.get('visited', 0)}/"
                     f"{rep.get('preplanned_total', 0)}, final state {rep.get('state')}, "
                     f"battery {rep.get('battery_pct', 0):.1f}%")
        if rep.get("error"):
            lines.append(f"    error: {rep['error']}")
        st = result.stats.get(rid, {})
        for sid, c in st.get("cameras", {}).items():
            dropped = sum(o["dropped"] for o in c["outlets"])
            lines.append(f"    camera {sid}: {c['frames']} frames rendered ({c['render_ms_median']:.1f} ms median), "
                         f"{rep.get('frames_dropped_at_camera', 0)} dropped at the camera, {dropped} dropped by busy "
                         f"consumers")
        for a in st.get("analytics", []):
            extra = ""
            if "frames_with_detections" in a:
                extra = f", detections in {a['frames_with_detections']}/{a['frames']} frames"
            if "commands" in a:
                extra = f", {a['commands']} navigation commands"
            lines.append(f"    analytics {a['name']}: {a['processed']} items, {a['process_ms_median']:.1f} ms median{extra}")
        lat = result.latency.get(rid)
        if lat:
            lines.append(f"    per-frame latency over {lat['frames']} frames: end-to-end median "
                         f"{lat['e2e_ms']['median']:.1f} ms (p99 {lat['e2e_ms']['p99']:.1f}), inference median "
                         f"{lat['inference_ms']['median']:.1f} ms, framework overhead median "
                         f"{lat['overhead_ms']['median']:.1f} ms (p99 {lat['overhead_ms']['p99']:.1f})")
    if result.recording:
        total = sum(result.recording_counts.values())
        lines.append(f"  recording: {result.recording} ({total} messages on {len(result.recording_counts)} channels)")
    return "\n".join(lines)

