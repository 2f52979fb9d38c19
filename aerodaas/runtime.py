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
    live: str | None = None  # serve the run to Foxglove over WebSocket on this HOST:PORT (aerodaas.live)
    #: start Ray in the background as soon as the application's Environment is validated (``aerodaas run``): an
    #: invalid environment then fails before any Ray process exists, and a valid one overlaps Ray's start with
    #: building the rest of the application
    early_ray: bool = False


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
    #: the recorder's failure (disk full, I/O error) or None: ``{error, last_recorded_ns, finished, ...}``; a run
    #: whose recording failed is not ``ok`` (exit code 1)
    recording_failure: dict[str, Any] | None = None
    recording_lost: int = 0
    recording_start_ns: int | None = None  # log time of sim time 0 (ns)

    @property
    def ok(self) -> bool:
        return self.outcome == "success" and self.recording_failure is None


_STARTED_RAY = False
#: stop signals received (SIGINT/SIGTERM through :func:`request_stop`), and whether raising KeyboardInterrupt in the
#: main thread is safe right now: while the application is built and while a mission runs, yes; while actors are
#: being set up or torn down, no (an exception inside a Ray call there can leave the core worker half shut down and
#: abort the process: exit 134 instead of 143, the recording unfinished) — the stop is then taken at the next
#: safe point, which ends the mission as ``interrupted`` with the recording finished
STOP_SIGNALS: list[int] = []
_RAISE_OK = [True]


def request_stop(signum: int) -> None:
    """Called by the CLI's SIGINT/SIGTERM handler (main thread): record the stop and raise KeyboardInterrupt when
    that is safe now; otherwise the run stops at its next safe point."""
    STOP_SIGNALS.append(signum)
    if _RAISE_OK[0]:
        raise KeyboardInterrupt(f"signal {signum}")
_EARLY: dict[str, Any] = {}  # the background start of Ray (start_ray_early)


def _init_ray(address: str | None) -> None:
    global _STARTED_RAY
    import ray

    if address:
        ray.init(address=address, log_to_driver=True, include_dashboard=False)
    else:
        # address="local": always a fresh cluster of our own, never one that `ray start` left on this machine
        # num_cpus=1: hosts reserve no CPU (they are num_cpus=0 actors), so the CPU resource only sizes Ray's
        # pool of prestarted workers: one, which the edge host takes (no idle 80 MB worker left around)
        for attempt in range(3):
            try:
                ray.init(address="local", labels={"tier": "edge"}, include_dashboard=False, log_to_driver=True,
                         num_cpus=1, configure_logging=True, logging_level="warning")
                break
            except Exception as e:  # noqa: BLE001 - Ray raises a bare Exception for this one
                # Ray gives its raylet a fixed 30 s to register with the GCS (ray/_private/node.py); a heavily
                # loaded machine can miss that: start again (at most 3 times) rather than fail the run
                if "timed out during startup" not in str(e) or attempt == 2:
                    raise
                ray.shutdown()
        _STARTED_RAY = True


def start_ray_early(address: str | None = None) -> None:
    """Start (or connect to) Ray in a background thread while the application is imported and built; the next
    :func:`ensure_ray` waits for it. Ray's processes are tied to the thread that started them
    (``PR_SET_PDEATHSIG``), so that thread stays alive, idle, for the life of the driver."""
    import threading

    if _EARLY:
        return
    ready = threading.Event()
    _EARLY.update(ready=ready, error=None, address=address)

    def keeper() -> None:
        import logging

        class _NoSigtermNotice(logging.Filter):  # the CLI installs its own SIGTERM handler in the main thread
            def filter(self, record: logging.LogRecord) -> bool:
                return not str(record.msg).startswith("SIGTERM handler is not set")

        logging.getLogger("ray._private.worker").addFilter(_NoSigtermNotice())
        try:
            _init_ray(address)
        except BaseException as e:  # surfaced by ensure_ray in the main thread
            _EARLY["error"] = e
        ready.set()
        threading.Event().wait()

    threading.Thread(target=keeper, name="aerodaas-ray-keeper", daemon=True).start()


class RayStartError(RuntimeError):
    """Ray could not be started or reached (the message says which and why); ``aerodaas run`` exits 1 with it."""


def ensure_ray(address: str | None = None) -> bool:
    """Connect to (``address``) or start a local Ray; returns True when the cluster has ``tier=cloud`` nodes.
    Raises :class:`RayStartError`."""
    import ray

    where = f"the Ray cluster at {address!r}" if address else "a local Ray"
    if _EARLY and _EARLY["address"] == address:
        _EARLY["ready"].wait()
        if _EARLY["error"] is not None:
            err, _EARLY["error"] = _EARLY["error"], None
            _EARLY.clear()
            if isinstance(err, KeyboardInterrupt):
                raise err
            raise RayStartError(f"could not start {where}: {type(err).__name__}: {err}") from err
    if not ray.is_initialized():
        try:
            _init_ray(address)
        except Exception as e:  # noqa: BLE001 - Ray raises bare Exceptions (node start time-outs, ...)
            raise RayStartError(f"could not start {where}: {type(e).__name__}: {e}") from e
    return any(n.get("Labels", {}).get("tier") == "cloud" for n in ray.nodes() if n.get("Alive"))


def shutdown_ray() -> None:
    global _STARTED_RAY
    import ray

    if _EARLY:
        _EARLY["ready"].wait()
    if _STARTED_RAY and ray.is_initialized():
        ray.shutdown()
    _STARTED_RAY = False
    _EARLY.clear()


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


class ComponentHandle:
    """A component inside a host actor, used like an actor handle: ``h.status.remote()`` calls
    ``component.status()`` in its host process and returns an ObjectRef."""

    def __init__(self, host: Any, cid: str) -> None:
        self.host, self.cid = host, cid

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        host, cid = self.host, self.cid

        class _Method:
            def remote(self, *args: Any, **kwargs: Any) -> Any:
                return host.call.remote(cid, name, *args, **kwargs)

        return _Method()

    def __repr__(self) -> str:
        return f"ComponentHandle({self.cid!r})"


@dataclass
class _Plan:
    """Where every component goes: host specs by tier, the routes between components, and per-robot ids."""

    specs: dict[str, dict]
    routes: dict[str, list]
    location: dict[str, str]
    robots: dict[str, dict]
    analytics_cids: dict[int, str]


def _plan(env, robots: list, graphs: dict, scheds: dict, sim: SimulationConfig, record: str | None,
          epoch_ns: int, scheduled: dict[int, Any] | None = None, live: str | None = None) -> _Plan:
    """Place components on hosts (one per tier in use: "edge" has the drones, cameras, schedulers, the recorder and
    the analytics deployed on edge compute; "cloud" the analytics deployed on cloud compute) and compute the
    routes from every stream producer to its subscribers. Analytics placed per frame by the analytics scheduler
    (``scheduled``: id(analytics) -> analytics) live on the edge host, whose dispatcher decides edge or cloud."""
    scheduled = scheduled or {}
    specs: dict[str, dict] = {"edge": {"sim": sim.model_dump(), "world": env.cfg.world.model_dump(mode="json"),
                                       "robots": [], "analytics": []}}
    if record or live:  # the recorder also feeds the live view; without --record it writes no file
        specs["edge"]["record"] = {"path": os.path.abspath(record) if record else None, "live": live, "meta": {
            "environment": env.cfg.name, "robots": ",".join(r.id for r in robots), "speedup": str(sim.speedup),
            "lockstep": str(sim.lockstep), "aerodaas": "0.1.0"}}
    location: dict[str, str] = {}
    acid: dict[int, str] = {}
    for r in robots:
        for a in graphs[r.id]:
            if id(a) in acid:
                continue  # shared by several robots: one instance
            cid = f"{a.name}#{len(acid) + 1}"
            acid[id(a)] = cid
            tier = "edge" if id(a) in scheduled else a.compute.tier
            specs.setdefault(tier, {"sim": sim.model_dump(), "robots": [], "analytics": []})
            if tier != "edge" and (record or live):  # e.g. cloud analytics: recorded by the edge recorder
                specs[tier]["record_remote"] = "edge"
            buffer = sum(s.buffer for s in a.inputs) or 1  # a shared analytics keeps each input's share
            specs[tier]["analytics"].append({"cid": cid, "name": a.name, "obj": a, "buffer": buffer,
                                             "scheduled": id(a) in scheduled})
            location[cid] = tier
    routes: dict[str, list] = {}
    robot_ids: dict[str, dict] = {}

    def subs_of(stream, sched, sched_cid) -> list[tuple]:
        out = [(acid[id(sub)], "in", stream.buffer) for sub in stream.subscribers if id(sub) in acid]
        for st, prio, replace in sched.stream_inputs:
            if st is stream:
                out.append((sched_cid, f"priority:{prio}" + (":replace" if replace else ""), 4))
        return out

    for r in robots:
        sched = scheds[r.id]
        preplanned = sum(sum(1 for i in m.items if type(i).__name__ == "Waypoint")
                         for m in sched._missions if m.distance_driven)
        ids = {"drone": f"{r.id}/drone", "scheduler": f"{r.id}/scheduler", "cameras": {}, "odom": [], "stat": []}
        cams = []
        for s in r.sensors.values():
            cid = f"{r.id}/{s.id}"
            if s.type == "camera" and (s.get_data_stream().subscribers or record or live):
                cams.append({"cid": cid, "sensor": s.id, "props": dict(s.cfg.properties)})
                ids["cameras"][s.id] = cid
            elif s.type == "odometry":
                ids["odom"].append(cid)
            elif s.type == "stat_stream":
                ids["stat"].append(cid)
            else:
                continue
            routes[cid] = subs_of(s.get_data_stream(), sched, ids["scheduler"])
        for a in graphs[r.id]:
            routes.setdefault(acid[id(a)], [])
            for sub in subs_of(a.output, sched, ids["scheduler"]):
                if sub not in routes[acid[id(a)]]:
                    routes[acid[id(a)]].append(sub)
        specs["edge"]["robots"].append({"robot": r.cfg.model_dump(mode="json"), "drone_cid": ids["drone"],
                                        "scheduler_cid": ids["scheduler"], "scheduler": sched,
                                        "preplanned": preplanned, "cameras": cams,
                                        "odom_cids": [c for c in ids["odom"] if routes.get(c)],
                                        "stat_cids": [c for c in ids["stat"] if routes.get(c)]})
        for cid in [ids["drone"], ids["scheduler"], *ids["cameras"].values(), *ids["odom"], *ids["stat"]]:
            location[cid] = "edge"
        robot_ids[r.id] = ids
    return _Plan(specs, routes, location, robot_ids, acid)


def _scheduled_analytics(env, graphs: dict) -> dict[int, Any]:
    """The analytics the environment's analytics scheduler places per frame (id -> analytics): those named in
    ``analytics_scheduler.models``. Raises ConfigError for a named analytics the application does not have, two
    scheduled analytics sharing a name, or one that is not fed by camera frames."""
    from .config import ConfigError

    cfg = env.cfg.analytics_scheduler
    if cfg.name == "default":
        return {}
    every = {id(a): a for g in graphs.values() for a in g}
    out = {i: a for i, a in every.items() if a.name in cfg.models}
    names = [a.name for a in out.values()]
    for name in cfg.models:
        if name not in names:
            raise ConfigError(f"analytics_scheduler.models.{name}: the application has no analytics named {name!r} "
                              f"(it has {sorted({a.name for a in every.values()})})")
        if names.count(name) > 1:
            raise ConfigError(f"analytics_scheduler.models.{name}: {names.count(name)} analytics share the name "
                              f"{name!r}; give each scheduled analytics its own name")
    for a in out.values():
        bad = [getattr(st.source, "id", repr(st.source)) for st in a.inputs
               if getattr(st.source, "type", None) != "camera"]
        if bad or not a.inputs:
            raise ConfigError(f"analytics_scheduler.models.{a.name}: a scheduled analytics takes camera frames, but "
                              f"{a.name!r} is fed by {bad or 'nothing'}")
    return out


def _start_scheduling(env, plan: _Plan, scheduled: dict, has_cloud: bool) -> list:
    """Start the cloud executors of the analytics scheduler (tier=cloud nodes, or this node without any) running
    copies of the scheduled analytics, and put the scheduler's spec into the edge host's spec. Returns the
    executors' handles (to kill at the end)."""
    from aerodaas.actors.cloud_executor import cloud_selector, start_cloud_executors

    cfg = env.cfg.analytics_scheduler
    analytics = {a.name: a for a in scheduled.values()}
    executors = start_cloud_executors(cfg.cloud_executors, mode="real", selector=cloud_selector(has_cloud),
                                      name_prefix="cloud-analytics", analytics=analytics)
    plan.specs["edge"]["analytics_scheduler"] = {
        "name": cfg.name, "workload": cfg.resolved_workload(env.cfg), "executors": executors,
        "network": list(cfg.network), "jpeg_quality": cfg.jpeg_quality, "seed": 0}
    return executors


def _robot_schedulers(env, robots: list) -> dict[str, Any]:
    """Each robot's trajectory scheduler. Robots that share one scheduler object (the application plugged one into
    the environment) get a fork each, holding the missions that robot navigates. Raises ValueError for a queued
    mission that no robot navigates when several robots share the scheduler (its drone would be a guess)."""
    by_sched: dict[int, list] = {}
    for r in robots:
        by_sched.setdefault(id(r.scheduler or env.trajectory_scheduler()), []).append(r)
    out: dict[str, Any] = {}
    for group in by_sched.values():
        sched = group[0].scheduler or env.trajectory_scheduler()
        if len(group) == 1:
            out[group[0].id] = sched
            continue
        owned: dict[str, list] = {r.id: [] for r in group}
        for m in sched._missions:
            owners = [r for r in group if any(w is i for nav in r.navigations for w in nav.waypoints for i in m.items)]
            if not owners:
                raise ValueError(f"mission {m.name!r} (priority {m.priority}) is queued in the shared trajectory scheduler "
                                 f"but no robot navigates it; call robot.navigate(...) for one of "
                                 f"{[r.id for r in group]}")
            owned[owners[0].id].append(m)
        for r in group:
            out[r.id] = sched.fork(owned[r.id])
    return out


def run_mission(env, robots: list, timeout: float | None = None) -> MissionResult:
    """Start the hosts for ``robots`` of ``env``, fly, and tear down. See the module docstring."""
    import ray

    from aerodaas.actors.host import HostActor

    opts = OPTIONS
    timeout = opts.timeout if opts.timeout is not None else timeout
    sim = SimulationConfig.model_validate(env.cfg.simulation.model_dump())
    if opts.speedup is not None:
        sim.speedup = opts.speedup
    if opts.lockstep is not None:
        sim.lockstep = opts.lockstep
    _check_clocks(robots, sim)

    # ---- validate everything before any actor starts
    if opts.record:
        from .recording import check_record_path

        check_record_path(opts.record)  # ValueError naming the path: before Ray, no folder created
    graphs = {}
    scheds = _robot_schedulers(env, robots)
    for r in robots:
        analytics, _ = _collect_graph(r)
        for a in analytics:
            if a.compute is None:
                a.deploy(env.get_compute_resources()[0])
            check = getattr(a, "check", None)
            if callable(check):
                check()
            if getattr(a, "on_error", "continue") not in ("continue", "abort"):
                from .config import ConfigError

                raise ConfigError(f"analytics {a.name!r}: on_error must be 'continue' or 'abort', got "
                                  f"{getattr(a, 'on_error')!r}")
        graphs[r.id] = analytics
        _check_preplanned(r, scheds[r.id])
        _check_autopilot_mission(r, scheds[r.id], opts.hitl if opts.hitl is not None else env.cfg.hitl.enabled)
    scheduled = _scheduled_analytics(env, graphs)

    from .startup_probe import probe

    probe("app_built")
    t_start = time.monotonic()
    if STOP_SIGNALS:  # stopped while the app was built: nothing started, nothing to record
        raise KeyboardInterrupt(f"signal {STOP_SIGNALS[0]}")
    _RAISE_OK[0] = False  # from here on a stop signal is taken at the safe points (see request_stop)
    has_cloud = ensure_ray(opts.address)
    probe("ray_ready")
    epoch_ns = time.time_ns()
    plan = _plan(env, robots, graphs, scheds, sim, opts.record, epoch_ns, scheduled, opts.live)
    hosts: dict[str, Any] = {}
    cloud_executors: list = []
    handles: dict[str, dict] = {}
    hitl = None
    reports: dict[str, dict] = {}
    stats: dict[str, Any] = {}
    latency: dict[str, Any] = {}
    counts: dict[str, int] = {}
    rec_report: dict[str, Any] = {}
    try:
        if scheduled:
            cloud_executors = _start_scheduling(env, plan, scheduled, has_cloud)
        for tier, spec in plan.specs.items():
            hosts[tier] = HostActor.options(label_selector=_selector(tier, has_cloud), name=None).remote(
                tier, tier, epoch_ns, sim.lockstep)
        described = ray.get([hosts[t].setup.remote(spec) for t, spec in plan.specs.items()])
        for d in described:
            if d.get("live_url"):
                print(f"aerodaas: live view at {d['live_url']} (Foxglove: Open connection -> Foxglove WebSocket)",
                      flush=True)
        tiers = {t: t for t in hosts}
        ray.get([h.connect.remote(plan.routes, plan.location, tiers, hosts) for h in hosts.values()])
        probe("hosts_ready")
        edge = hosts["edge"]
        for r in robots:
            ids = plan.robots[r.id]
            a_handles = {cid: ComponentHandle(hosts[plan.location[cid]], cid)
                         for cid in (plan.analytics_cids[id(a)] for a in graphs[r.id])}
            handles[r.id] = {"robot": r, "drone": ComponentHandle(edge, ids["drone"]),
                             "scheduler": ComponentHandle(edge, ids["scheduler"]), "analytics": a_handles,
                             "cameras": {sid: ComponentHandle(edge, cid) for sid, cid in ids["cameras"].items()},
                             "sched_obj": r.scheduler or env.trajectory_scheduler()}
            r._handle = handles[r.id]["drone"]
            if scheds[r.id] is handles[r.id]["sched_obj"]:  # not shared: live add/clear go to this robot's queue
                handles[r.id]["sched_obj"]._remote = handles[r.id]["scheduler"]
            for s in r.sensors.values():
                s.get_data_stream()._runtime_getter = _pull_getter(s, handles[r.id])
            for a in graphs[r.id]:
                h = a_handles[plan.analytics_cids[id(a)]]
                a.output._runtime_getter = (lambda h=h: ray.get(h.get_latest.remote()))

        hcfg = env.cfg.hitl
        if opts.hitl if opts.hitl is not None else hcfg.enabled:
            from .hitl import HitlServer

            hitl = HitlServer({rid: {"drone": h["drone"], "scheduler": h["scheduler"]} for rid, h in handles.items()},
                              host=hcfg.host, port=opts.hitl_port if opts.hitl_port is not None else hcfg.port,
                              token=hcfg.token, docs=hcfg.docs).start()
            env.hitl = hitl
            shown = hitl.token if hitl.generated_token else "(the token from environment.json)"
            print(f"aerodaas: human-in-the-loop API at {hitl.url}  bearer token: {shown}", flush=True)
        for h in handles.values():
            for hook in h["robot"]._start_hooks:
                hook(h["robot"])
        run_ref = edge.run.remote(timeout)
        reports = _wait_with_progress(run_ref, handles, opts.progress)
        _RAISE_OK[0] = False
        stats, latency = _collect_stats(handles, hosts)
    finally:
        _RAISE_OK[0] = False
        if hitl is not None:
            hitl.stop()
            env.hitl = None
        for tier, h in sorted(hosts.items(), key=lambda th: th[0] == "edge"):  # the edge recorder closes last
            try:
                got = ray.get(h.close.remote(), timeout=60)
                if tier == "edge":
                    counts = got
                    rec_report = ray.get(h.recording_report.remote(), timeout=60)
            except Exception as e:  # pragma: no cover - reported, never silently lost
                print(f"aerodaas: warning: host {tier!r} could not be closed cleanly (recording: {opts.record}): {e}",
                      file=sys.stderr)
        for h in handles.values():
            h["robot"]._handle = None
            h["sched_obj"]._remote = None
            for s in h["robot"].sensors.values():
                s.get_data_stream()._runtime_getter = None
        for h in [*hosts.values(), *cloud_executors]:
            try:
                ray.kill(h, no_restart=True)
            except Exception:  # an executor on a lost node is already gone
                pass
    _RAISE_OK[0] = True  # back in the application
    for r in robots:
        reports.setdefault(r.id, {"robot": r.id, "outcome": "failed", "error": "no report (the run did not start)"})
    outcomes = [rep.get("outcome") or "failed" for rep in reports.values()]
    outcome = "success" if outcomes and all(o == "success" for o in outcomes) else next(
        (o for o in outcomes if o != "success"), "failed")
    result = MissionResult(outcome=outcome, robots=reports, stats=stats, latency=latency, recording=opts.record,
                           wall_s=time.monotonic() - t_start, recording_counts=counts,
                           recording_failure=rec_report.get("failure"), recording_lost=rec_report.get("lost", 0),
                           recording_start_ns=epoch_ns)
    for h in handles.values():
        for hook in h["robot"]._end_hooks:
            hook(h["robot"], result)
    return result


def _check_clocks(robots: list, sim: SimulationConfig) -> None:
    """Real vehicles live in real time: lock-step needs every robot on the simulator. Raises ConfigError. A run
    that only replays logs runs its clock at the replay rate (so odometry keeps its rate in log time)."""
    from .config import ConfigError

    if robots and all(r.cfg.backend == "replay" for r in robots):
        sim.speedup = max(r.cfg.replay.rate for r in robots)

    real = [r.id for r in robots if r.cfg.backend != "sim"]
    if real and sim.lockstep:
        raise ConfigError(f"simulation.lockstep: true needs every robot on backend 'sim'; {real} fly real or "
                          f"emulated vehicles, which cannot wait for the analytics (set lockstep to false)")


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


def _check_autopilot_mission(robot, sched, hitl_on: bool) -> None:
    """``mavlink.use_autopilot_mission``: the robot's navigation must be a static, pre-planned waypoint list that
    an uploaded mission can express. Raises ConfigError naming the field and the reason: analytics navigating
    through the scheduler, the HITL API on (both add waypoints mid-flight), time-driven navigation, velocity
    commands or a land/rtl action before the end (MissionFileError), or no waypoints at all."""
    from .config import ConfigError
    from .missionfile import MissionFileError, navigation_to_plan
    from .models import AeroNavigation, SchedulingType, Waypoint

    mc = robot.cfg.mavlink
    if robot.cfg.backend != "mavlink" or mc is None or not mc.use_autopilot_mission:
        return
    field = f"robots[{robot.id!r}].mavlink.use_autopilot_mission: true"
    if sched.stream_inputs:
        raise ConfigError(f"{field} flies a mission uploaded before take-off, but {len(sched.stream_inputs)} analytics "
                          "stream(s) navigate this robot through its trajectory scheduler (analytics-driven "
                          "navigation); set it to false to fly with position/velocity targets")
    if hitl_on:
        raise ConfigError(f"{field} flies a mission uploaded before take-off, but the human-in-the-loop API is on "
                          "(hitl.enabled / --hitl) and could add waypoints mid-flight; turn one of them off")
    timed = [m.name for m in sched._missions if not m.distance_driven]
    if timed:
        raise ConfigError(f"{field}: navigation {timed} is time-driven; an autopilot mission holds only "
                          "distance-driven waypoints")
    items = sched.queued()
    if not any(isinstance(i, Waypoint) for i in items):
        raise ConfigError(f"{field}: robot {robot.id!r} has no pre-planned waypoints to upload "
                          "(call drone.navigate(...) before start_mission())")
    try:
        navigation_to_plan(AeroNavigation(waypoints=items, scheduling_type=SchedulingType.ORDERED), robot.cfg.home,
                           "land", takeoff_altitude=robot.cfg.takeoff_altitude)
    except MissionFileError as e:
        raise ConfigError(f"{field}: the navigation cannot be an autopilot mission: {e}") from None


def _pull_getter(sensor, h: dict):
    import ray

    def get():
        if sensor.type == "camera" and sensor.id in h["cameras"]:
            return ray.get(h["cameras"][sensor.id].get_latest.remote())
        st = ray.get(h["drone"].status.remote())
        return st if sensor.type == "stat_stream" else ray.get(h["drone"].report.remote()).get("position")

    return get


def _wait_with_progress(run_ref: Any, handles: dict, progress: bool) -> dict:
    """Wait for the edge host's run to end, showing live progress; Ctrl-C ends every mission cleanly."""
    import ray

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
        if STOP_SIGNALS:  # a stop arrived while the actors were set up: end at once, cleanly
            raise KeyboardInterrupt(f"signal {STOP_SIGNALS[0]}")
        _RAISE_OK[0] = True
        while True:
            ready, _ = ray.wait([run_ref], num_returns=1, timeout=0.5)
            if ready:
                reports = ray.get(run_ref)
                break
            if progress:
                lines = _progress_lines(handles, t0)
                if live is not None:
                    from rich.text import Text

                    live.update(Text("\n".join(lines)))
                elif time.monotonic() - last_print > 5.0:
                    print("\n".join(lines), flush=True)
                    last_print = time.monotonic()
    except KeyboardInterrupt:
        _RAISE_OK[0] = False
        interrupted = True
        for h in handles.values():
            try:
                ray.get(h["drone"].end_mission.remote("interrupted"), timeout=5)
            except Exception:
                pass
        try:
            reports = ray.get(run_ref, timeout=20)
        except Exception as e:
            reports = {rid: {"robot": rid, "outcome": "interrupted", "error": str(e)} for rid in handles}
    finally:
        if live is not None:
            live.stop()
    if interrupted:
        for rep in reports.values():
            rep["outcome"] = "interrupted"
    return reports


def _progress_lines(handles: dict, t0: float) -> list[str]:
    import ray

    lines = []
    for rid, h in handles.items():
        try:
            st = ray.get(h["drone"].status.remote(), timeout=2)
        except Exception:
            continue
        if st.get("outcome"):
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
                cloud = (s.get("frames_by_tier") or {}).get("cloud")
                if cloud:  # frames the analytics scheduler sent to the cloud (counted above too)
                    dets += f" (cloud {cloud})"
        x, y, z = st["position"]
        link = "" if st.get("link_ok", True) else " LINK LOST"
        lines.append(f"[{rid}] t={st['t']:6.1f}s {st['state']:<13} waypoint {st['visited']}/{st['preplanned_total']} "
                     f"pos=({x:6.1f},{y:6.1f},{z:5.1f}) battery {_pct(st['battery_pct'])} "
                     f"camera {fps:5.1f} FPS dropped {st['frames_dropped_at_camera']}{dets}{link}")
    return lines


def _collect_stats(handles: dict, hosts: dict) -> tuple[dict, dict]:
    import ray

    host_stats = {tier: ray.get(h.stats.remote()) for tier, h in hosts.items()}
    every = {cid: s for hs in host_stats.values() for cid, s in hs.items()}
    stats: dict[str, Any] = {"_hosts": {t: hs.get("_host", {}) for t, hs in host_stats.items()}}
    sched_rep = host_stats.get("edge", {}).get("_analytics_scheduler")
    if sched_rep:
        stats["analytics_scheduler"] = sched_rep
    latency: dict[str, Any] = {}
    for rid, h in handles.items():
        s: dict[str, Any] = {"scheduler": every.get(h["scheduler"].cid, {})}
        s["cameras"] = {sid: every.get(c.cid, {}) for sid, c in h["cameras"].items()}
        s["analytics"] = [every.get(cid, {}) for cid in h["analytics"]]
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
                     f"battery {_pct(rep.get('battery_pct', 0))}")
        if rep.get("error"):
            lines.append(f"    error: {rep['error']}")
        st = result.stats.get(rid, {})
        for sid, c in st.get("cameras", {}).items():
            if not c:
                continue
            dropped = sum(a.get("dropped", 0) for a in st.get("analytics", []) if a)
            lines.append(f"    camera {sid}: {c['frames']} frames rendered ({c['render_ms_median']:.1f} ms median), "
                         f"{rep.get('frames_dropped_at_camera', 0)} dropped at the camera, {dropped} dropped by busy "
                         f"consumers")
        for a in st.get("analytics", []):
            if not a:
                continue
            extra = ""
            if "frames_with_detections" in a:
                extra = f", detections in {a['frames_with_detections']}/{a['frames']} frames"
            if "commands" in a:
                extra = f", {a['commands']} navigation commands"
            if a.get("failures"):
                extra += (f", {a['failures']} FAILED items (on_error={a.get('on_error')}; last: "
                          f"{a.get('last_failure')})")
            lines.append(f"    analytics {a['name']}: {a['processed']} items, {a['process_ms_median']:.1f} ms median{extra}")
        lat = result.latency.get(rid)
        if lat:
            lines.append(f"    per-frame latency over {lat['frames']} frames: end-to-end median "
                         f"{lat['e2e_ms']['median']:.1f} ms (p99 {lat['e2e_ms']['p99']:.1f}), inference median "
                         f"{lat['inference_ms']['median']:.1f} ms, framework overhead median "
                         f"{lat['overhead_ms']['median']:.1f} ms (p99 {lat['overhead_ms']['p99']:.1f})")
    sr = result.stats.get("analytics_scheduler")
    if sr:
        st = sr.get("states", {})
        lines.append(f"  analytics scheduler {sr.get('scheduler')}: {sr.get('submitted', 0)} tasks, on time "
                     f"{100 * sr.get('on_time_rate', 0):.1f}% (edge {sr.get('tiers', {}).get('edge', 0)}, cloud "
                     f"{sr.get('tiers', {}).get('cloud', 0)}), utility {sr.get('utility', 0):.0f}, cloud cost "
                     f"{sr.get('cloud_cost', 0):.0f}; " + ", ".join(f"{k} {v}" for k, v in st.items() if v))
        for ev in (sr.get("cloud") or {}).get("losses", []):
            lines.append(f"    cloud executor {ev.get('name')} lost at {ev.get('at_s', 0):.1f} s ({ev.get('error')}): "
                         f"{ev.get('in_flight', 0)} tasks in flight, {ev.get('retried', 0)} retried, "
                         f"{ev.get('failed', 0)} failed")
    if result.recording:
        total = sum(result.recording_counts.values())
        fail = result.recording_failure
        if fail is None:
            lines.append(f"  recording: {result.recording} ({total} messages on {len(result.recording_counts)} "
                         f"channels)")
        else:
            at = fail.get("last_recorded_ns")
            held = f"up to {(at - result.recording_start_ns) / 1e9:.1f} s" if at and result.recording_start_ns else \
                "nothing"
            state = "finished" if fail.get("finished") else ("UNFINISHED (" + str(fail.get("finish_error")) +
                                                              "; run `aerodaas recover FILE` when there is room)")
            lines.append(f"  recording: FAILED: {fail.get('error')}; {result.recording} holds {held} "
                         f"({fail.get('messages_in_file', '?')} messages, {state}); "
                         f"{result.recording_lost} later messages were not recorded")
    return "\n".join(lines)



def _pct(v: float | None) -> str:
    """A battery percentage for humans; None (a log without battery data) is "unknown"."""
    return "unknown" if v is None else f"{v:5.1f}%"
